//! Threads that yield to the tracker: Linux's idle scheduling policy (`SCHED_IDLE`), in
//! which a thread runs only on CPU time nothing else wants, and the way back to the normal
//! policy (`SCHED_OTHER`, which keeps the thread's nice value) when one has waited too long.
//!
//! Coming back takes CAP_SYS_NICE or an RLIMIT_NICE that allows the thread's nice value
//! (most distributions set 0 for users). A thread that could not come back would starve
//! beside a busy stage (a SAM segmenter takes both cores of an edge machine), so callers
//! use the idle policy only where [`may_leave_idle`] says it can be undone. Elsewhere (not
//! Linux) threads keep their policy.

/// The kernel id of the calling thread (0 where there is none to name).
pub fn this_thread() -> i32 {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: gettid has no preconditions.
        unsafe { libc::gettid() }
    }
    #[cfg(not(target_os = "linux"))]
    {
        0
    }
}

/// Whether a thread of this process may enter the idle policy and leave it again (tried
/// once on a thread of its own, then remembered).
pub fn may_leave_idle() -> bool {
    static ANSWER: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ANSWER.get_or_init(|| {
        std::thread::spawn(|| {
            let tid = this_thread();
            set_idle(tid, true) && set_idle(tid, false)
        })
        .join()
        .unwrap_or(false)
    })
}

/// Puts thread `tid` of this process in the idle policy (`idle`) or the normal one; false
/// if refused or not on Linux (the thread then runs in the policy it had).
pub fn set_idle(tid: i32, idle: bool) -> bool {
    #[cfg(target_os = "linux")]
    {
        if tid == 0 {
            return false;
        }
        let policy = match idle {
            true => libc::SCHED_IDLE,
            false => libc::SCHED_OTHER,
        };
        let param = libc::sched_param { sched_priority: 0 };
        // SAFETY: `tid` is a thread of this process (or gone, which only fails); `param` is
        // a valid, initialised struct.
        let rc = unsafe { libc::sched_setscheduler(tid, policy, &param) };
        rc == 0
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (tid, idle);
        false
    }
}

/// Whether thread `tid` of this process is in the idle policy now.
pub fn is_idle(tid: i32) -> bool {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: reads the scheduling policy of a thread of this process.
        tid != 0 && unsafe { libc::sched_getscheduler(tid) } == libc::SCHED_IDLE
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = tid;
        false
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    #[test]
    fn a_thread_goes_idle_and_comes_back_where_it_may() {
        let may = may_leave_idle();
        let (idle, back) = std::thread::spawn(|| {
            let tid = this_thread();
            let went = set_idle(tid, true);
            let idle = is_idle(tid);
            let back = set_idle(tid, false) && !is_idle(tid);
            (went && idle, back)
        })
        .join()
        .expect("thread");
        // Going idle is always allowed; coming back exactly where the probe said so.
        assert!(idle);
        assert_eq!(back, may);
        // The caller's thread was never touched.
        assert!(!is_idle(this_thread()));
    }
}
