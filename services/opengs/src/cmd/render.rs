//! `opengs render`: render a saved map from one pose into PNGs (colour, depth, labels).

use std::path::PathBuf;

use anyhow::Context;
use opengs_pipeline::cli_values;
use opengs_splat::{args, render, write_render_pngs, Camera, RenderRequest};

use crate::cmd::map_input::load_map;

#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// Map in 3DGS PLY format (with or without a `label` property).
    #[arg(long)]
    pub map: PathBuf,
    /// Camera-to-world pose, TUM order: "tx ty tz qx qy qz qw".
    #[arg(long, allow_hyphen_values = true)]
    pub pose: String,
    /// Pinhole intrinsics "fx fy cx cy" (OpenCV convention).
    #[arg(long, allow_hyphen_values = true)]
    pub intrinsics: String,
    /// Image size WxH, e.g. 640x480.
    #[arg(long, value_parser = args::parse_size)]
    pub size: (u32, u32),
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Near plane in metres: Gaussians closer than this are culled.
    #[arg(long, default_value_t = opengs_splat::DEFAULT_NEAR, value_parser = cli_values::non_negative_f32)]
    pub near: f32,
    /// Also compute the per-pixel top-K Gaussians (K = 50) and write topk_count.png.
    #[arg(long)]
    pub top_k: bool,
    /// Refuse a map with NaN or infinite values instead of leaving those Gaussians out.
    #[arg(long)]
    pub strict: bool,
}

pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    let (w, h) = args.size;
    let intrinsics = args::parse_intrinsics(&args.intrinsics, w, h).map_err(anyhow::Error::msg)?;
    let pose = opengs_geometry::parse_tum_pose(&args.pose)
        .with_context(|| format!("--pose '{}'", args.pose))?;
    let request = RenderRequest {
        top_k: args.top_k.then_some(opengs_splat::DEFAULT_TOP_K),
        ..RenderRequest::semantic(opengs_splat::DEFAULT_TOP_K)
    };
    args::check_render_size(w, h, request.top_k)
        .map_err(anyhow::Error::msg)
        .context("--size")?;
    let map = load_map(&args.map, args.strict)?;
    let camera = Camera::from_pose(intrinsics, &pose, args.near);
    let t0 = std::time::Instant::now();
    let rendered = render(&map, &camera, &request);
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    let out = &rendered.output;
    let mut files = write_render_pngs(out, &args.out)
        .with_context(|| format!("writing PNGs to {}", args.out.display()))?;
    if let Some(tk) = &out.top_k {
        let path = args.out.join("topk_count.png");
        image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, tk.count.clone())
            .context("top-K count image size")?
            .save(&path)
            .with_context(|| format!("writing {}", path.display()))?;
        files.push(path);
    }
    let visible: u32 = out.visible_per_label.iter().flat_map(|m| m.values()).sum();
    println!(
        "rendered {} Gaussians ({} visible, {} labels) at {w}x{h} in {ms:.1} ms",
        map.len(),
        visible,
        out.visible_per_label.as_ref().map_or(0, |m| m.len()),
    );
    for f in files {
        println!("wrote {}", f.display());
    }
    Ok(())
}
