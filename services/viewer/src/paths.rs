//! The entity paths of the recording: one tree, so a 3D view of `world` shows the camera,
//! its frustum and images, the keyframe with its label maps, the trajectory and the map, and
//! the time series sit beside it.
//!
//! ```text
//! world                              axes (static); global label names and colours
//! world/camera                       tracked camera-to-world pose, every frame
//! world/camera/image                 pinhole (frustum)
//! world/camera/image/rgb             sensor RGB (JPEG)
//! world/camera/image/depth           sensor depth
//! world/trajectory                   verified camera positions, one polyline
//! world/keyframe                     pose of the newest keyframe
//! world/keyframe/image               its pinhole
//! world/keyframe/image/rgb           its RGB (JPEG)
//! world/keyframe/image/segments      segmenter label map (its own per-frame labels and classes)
//! world/keyframe/image/render        the mapper's GS Voting label render (global labels)
//! world/keyframe/image/consensus     the consensus' consistent label map (global labels)
//! world/map/gaussians                trackable Gaussians, coloured by global label
//! tracking/status                    lost and relocalised frames
//! tracking/overlap, tracking/inliers per frame
//! map/trackable_gaussians            per map update
//! stages                             stages ready (a restart shows as a second one), finished
//! latency/<stage>/{wait,process,total,since_sensor}_ms   per message a stage processed
//! dropped/<stage>                    inputs a stage dropped so far
//! final_work/<stage>                 steps done of the work after the end of the data
//! ```

pub const WORLD: &str = "world";
pub const CAMERA: &str = "world/camera";
pub const CAMERA_IMAGE: &str = "world/camera/image";
pub const CAMERA_RGB: &str = "world/camera/image/rgb";
pub const CAMERA_DEPTH: &str = "world/camera/image/depth";
pub const TRAJECTORY: &str = "world/trajectory";
pub const KEYFRAME: &str = "world/keyframe";
pub const KEYFRAME_IMAGE: &str = "world/keyframe/image";
pub const KEYFRAME_RGB: &str = "world/keyframe/image/rgb";
pub const SEGMENTS: &str = "world/keyframe/image/segments";
pub const RENDER: &str = "world/keyframe/image/render";
pub const CONSENSUS: &str = "world/keyframe/image/consensus";
pub const GAUSSIANS: &str = "world/map/gaussians";
pub const TRACKING_STATUS: &str = "tracking/status";
pub const TRACKING_OVERLAP: &str = "tracking/overlap";
pub const TRACKING_INLIERS: &str = "tracking/inliers";
pub const MAP_SIZE: &str = "map/trackable_gaussians";
pub const STAGE_EVENTS: &str = "stages";

/// What a stage's latency series measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LatencyPart {
    /// Input queued: from its sending to the start of work.
    Wait,
    /// Work on it.
    Process,
    /// Wait plus work.
    Total,
    /// From the sensor publishing the source frame to the end of this stage's work.
    SinceSensor,
}

impl LatencyPart {
    fn as_str(self) -> &'static str {
        match self {
            Self::Wait => "wait_ms",
            Self::Process => "process_ms",
            Self::Total => "total_ms",
            Self::SinceSensor => "since_sensor_ms",
        }
    }
}

/// Keeps a stage name from a message a single, harmless path part.
fn part(name: &str) -> String {
    let clean: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if clean.is_empty() {
        "_".to_string()
    } else {
        clean
    }
}

pub fn latency(stage: &str, what: LatencyPart) -> String {
    format!("latency/{}/{}", part(stage), what.as_str())
}

pub fn dropped(stage: &str) -> String {
    format!("dropped/{}", part(stage))
}

pub fn final_work(stage: &str) -> String {
    format!("final_work/{}", part(stage))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_paths_are_one_clean_part_each() {
        assert_eq!(
            latency("tracker", LatencyPart::Total),
            "latency/tracker/total_ms"
        );
        assert_eq!(
            latency("seg/../x y", LatencyPart::Wait),
            "latency/seg____x_y/wait_ms"
        );
        assert_eq!(dropped(""), "dropped/_");
        assert_eq!(final_work("mapper"), "final_work/mapper");
    }

    #[test]
    fn images_sit_under_their_pinholes_and_the_world() {
        for p in [CAMERA_RGB, CAMERA_DEPTH] {
            assert!(p.starts_with(&format!("{CAMERA_IMAGE}/")), "{p}");
        }
        for p in [KEYFRAME_RGB, SEGMENTS, RENDER, CONSENSUS] {
            assert!(p.starts_with(&format!("{KEYFRAME_IMAGE}/")), "{p}");
        }
        for p in [CAMERA, TRAJECTORY, KEYFRAME, GAUSSIANS] {
            assert!(p.starts_with(&format!("{WORLD}/")), "{p}");
        }
    }
}
