//! Mapping the synthetic room from tracked keyframes.

use opengs_datasets::{open_dataset, DatasetSpec};
use opengs_mapping::{DensifyInput, Mapper, MapperConfig, StoredKeyframe};
use opengs_splat::{render, RenderRequest};
use opengs_tracking::{DepthFrame, FrameTracker, TrackerConfig};

fn psnr(kf: &StoredKeyframe, mapper: &Mapper) -> f64 {
    let out = render(mapper.map(), &kf.camera, &RenderRequest::color_depth()).output;
    let mut se = 0.0;
    let mut n = 0usize;
    for (i, c) in out.color.iter().enumerate() {
        if kf.target.depth[i] <= 0.0 {
            continue;
        }
        for (ch, value) in c.iter().enumerate() {
            let d = (value.clamp(0.0, 1.0) - kf.target.rgb[ch][i]) as f64;
            se += d * d;
        }
        n += 3;
    }
    10.0 * (1.0 / (se / n as f64)).log10()
}

#[test]
fn keyframes_become_gaussians_and_optimisation_raises_psnr() {
    let mut spec: DatasetSpec = "synthetic".parse().expect("spec");
    spec.synthetic.frames = Some(40);
    let mut source = open_dataset(&spec).expect("dataset");
    let k = source.intrinsics();
    let mut tracker = FrameTracker::new(TrackerConfig::tum());
    let config = MapperConfig::default();
    let mut mapper = Mapper::new(config.clone());
    let mut first_kf = None;
    for i in 0..40 {
        let f = source.frame(i).expect("frame");
        let out = tracker.track(&DepthFrame {
            depth: &f.depth,
            depth_scale: f.depth_scale as f64,
            intrinsics: &k,
            timestamp: f.timestamp,
        });
        let (Some(_), Some(cloud)) = (out.keyframe, out.world_cloud()) else {
            continue;
        };
        let (points, covs) = (cloud.points, cloud.covariances);
        let input = DensifyInput {
            points: &points,
            covariances: &covs,
            pose: out.pose,
            intrinsics: k,
            rgb: &f.rgb,
            depth: &f.depth,
            depth_scale: f.depth_scale,
        };
        let kf = StoredKeyframe::new(
            i as u64,
            out.pose,
            k,
            &f.rgb,
            &f.depth,
            f.depth_scale,
            &config,
        );
        let added = mapper.add_keyframe(&input, kf.clone());
        assert!(
            added > 0 || first_kf.is_some(),
            "the first keyframe adds Gaussians"
        );
        first_kf.get_or_insert(kf);
    }
    let kf = first_kf.expect("a keyframe");
    assert!(mapper.keyframes() >= 2, "{} keyframes", mapper.keyframes());
    let before = psnr(&kf, &mapper);
    let means = mapper.map().means.clone();
    let t = std::time::Instant::now();
    for _ in 0..150 {
        mapper.step();
    }
    let ms = t.elapsed().as_secs_f64() * 1000.0 / 150.0;
    let after = psnr(&kf, &mapper);
    eprintln!("{} Gaussians, {} keyframes: PSNR {before:.2} → {after:.2} dB after 150 steps ({ms:.1} ms/step)", mapper.map().len(), mapper.keyframes());
    assert!(after > before + 3.0, "PSNR {before:.2} → {after:.2}");
    // Online the means stay where the keyframes' depth put them: the tracker registers
    // against them (MapperConfig::scene_extent).
    assert_eq!(mapper.map().len(), means.len(), "no pruning in 150 steps");
    let moved = (mapper.map().means.iter().zip(&means))
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(moved, 0, "{moved} of {} means moved online", means.len());
    let trackable = mapper.trackable();
    assert!(!trackable.means.is_empty());
}
