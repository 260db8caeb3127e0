//! How much memory a reader may still allocate, so that a size taken from a file or the
//! command line is refused with a message instead of aborting the process.

/// Bytes this process may still allocate: the least of the kernel's `MemAvailable`, the
/// address-space limit (`ulimit -v`) and the cgroup's limit, each less what is in use.
pub fn memory_budget() -> u64 {
    let limits = [available_ram(), address_space_left(), cgroup_left()];
    // Without /proc (not Linux) nothing is known: a generous fixed budget.
    limits.into_iter().flatten().min().unwrap_or(8 << 30)
}

/// `Err` naming `what` when `bytes` exceed [`memory_budget`].
pub fn check_memory(what: &str, bytes: u128) -> Result<(), String> {
    let budget = memory_budget();
    if bytes > budget as u128 {
        return Err(format!(
            "{what} would need {}, more than the {} of memory available",
            format_bytes(bytes),
            format_bytes(budget as u128)
        ));
    }
    Ok(())
}

/// `1.5 GiB`, `12.0 MiB`, `512 B`.
pub fn format_bytes(bytes: u128) -> String {
    const KIB: f64 = 1024.0;
    let b = bytes as f64;
    if b >= KIB * KIB * KIB * KIB {
        format!("{:.1} TiB", b / (KIB * KIB * KIB * KIB))
    } else if b >= KIB * KIB * KIB {
        format!("{:.1} GiB", b / (KIB * KIB * KIB))
    } else if b >= KIB * KIB {
        format!("{:.1} MiB", b / (KIB * KIB))
    } else {
        format!("{bytes} B")
    }
}

/// A `Key:  N kB` line of a /proc file, in bytes.
fn proc_kib(path: &str, key: &str) -> Option<u64> {
    let text = std::fs::read_to_string(path).ok()?;
    let line = text.lines().find(|l| l.starts_with(key))?;
    let kib: u64 = line[key.len()..].split_whitespace().next()?.parse().ok()?;
    kib.checked_mul(1024)
}

fn available_ram() -> Option<u64> {
    proc_kib("/proc/meminfo", "MemAvailable:")
}

/// The soft `RLIMIT_AS` less the address space already mapped.
fn address_space_left() -> Option<u64> {
    let limits = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = limits
        .lines()
        .find(|l| l.starts_with("Max address space"))?;
    let soft: u64 = line["Max address space".len()..]
        .split_whitespace()
        .next()?
        .parse()
        .ok()?;
    let used = proc_kib("/proc/self/status", "VmSize:").unwrap_or(0);
    Some(soft.saturating_sub(used))
}

/// cgroup v2 `memory.max` less `memory.current` ("max" means no limit).
fn cgroup_left() -> Option<u64> {
    let read = |name: &str| -> Option<u64> {
        std::fs::read_to_string(format!("/sys/fs/cgroup/{name}"))
            .ok()?
            .trim()
            .parse()
            .ok()
    };
    let max = read("memory.max")?;
    Some(max.saturating_sub(read("memory.current").unwrap_or(0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budget_is_positive_and_huge_requests_are_refused() {
        assert!(memory_budget() > 0);
        let e = check_memory("a test table", 1 << 70).expect_err("1 ZiB");
        assert!(e.starts_with("a test table would need"), "{e}");
        assert!(check_memory("a test table", 1024).is_ok());
        assert_eq!(format_bytes(512), "512 B");
        assert_eq!(format_bytes(3 << 29), "1.5 GiB");
    }
}
