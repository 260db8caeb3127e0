//! `opengs objects`: list, pick, extract, remove, move and rotate the objects of a finished map,
//! and show an edit before/after from one view. The work is done by `opengs_objects`; this file
//! reads the inputs, checks them all before anything is written, and prints or writes results.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use opengs_objects::{
    apply, compare_edit, extent_of, list_objects, pick_box, pick_pixel, ply_sh_degree,
    refuse_higher_bands, require_labels, split, Catalog, ObjectSummary, PixelBox, RigidMotion,
    Selection,
};
use opengs_pipeline::cli_values;
use opengs_splat::{args, render, write_ply_file, Camera, GaussianMap, RenderRequest};

use crate::cmd::map_input::{load_map, parse_map};

#[derive(Debug, clap::Args)]
pub struct ObjectsArgs {
    #[command(subcommand)]
    command: ObjectsCommand,
}

#[derive(Debug, clap::Subcommand)]
enum ObjectsCommand {
    /// One row per object: id, class, score, Gaussians, centroid, boxes, volume; largest first.
    List(ListArgs),
    /// Which object is at a pixel (--pixel) or in a box (--box) of a view, by GS Voting.
    Pick(PickArgs),
    /// Write the selected object(s) alone as a standard 3DGS PLY (labels kept).
    Extract(EditArgs),
    /// Write the map without the selected object(s).
    Remove(EditArgs),
    /// Write the map with the selected object(s) moved by --translate.
    Move(MoveArgs),
    /// Write the map with the selected object(s) turned about their centroid (or --about).
    Rotate(RotateArgs),
    /// Before/after PNG of an edit seen from one view (colour and labels, the object outlined).
    RenderEdit(RenderEditArgs),
}

/// The map to work on.
#[derive(Debug, clap::Args)]
struct SourceArgs {
    /// A run directory (its map.ply and labels.json) or a map .ply.
    source: PathBuf,
    /// Class names (a run's labels.json). Default: the run's, or the labels.json beside the .ply.
    #[arg(long)]
    labels: Option<PathBuf>,
    /// Refuse a map with NaN or infinite values instead of leaving those Gaussians out.
    #[arg(long)]
    strict: bool,
}

/// Which objects: exactly one of these.
#[derive(Debug, clap::Args)]
#[group(required = true, multiple = false)]
struct SelectArgs {
    /// Object label(s): --label 7 or --label 7,9.
    #[arg(long, value_delimiter = ',')]
    label: Vec<u32>,
    /// Every object of this class (from labels.json; case ignored).
    #[arg(long)]
    class: Option<String>,
    /// The object GS Voting gives at pixel U,V of the view (needs --pose, --intrinsics, --size).
    #[arg(long, value_name = "U,V", value_parser = parse_pixel)]
    pixel: Option<(u32, u32)>,
    /// The objects dominating the box X0,Y0,X1,Y1 of the view (pixels, corners included).
    #[arg(long = "box", value_name = "X0,Y0,X1,Y1", value_parser = parse_box)]
    rect: Option<PixelBox>,
}

/// A view, as `opengs render` takes it.
#[derive(Debug, clap::Args)]
struct ViewArgs {
    /// Camera-to-world pose, TUM order: "tx ty tz qx qy qz qw" (a trajectory.txt line without its timestamp).
    #[arg(long, allow_hyphen_values = true)]
    pose: Option<String>,
    /// Pinhole intrinsics "fx fy cx cy" (OpenCV convention).
    #[arg(long, allow_hyphen_values = true)]
    intrinsics: Option<String>,
    /// Image size WxH, e.g. 640x480.
    #[arg(long, value_parser = args::parse_size)]
    size: Option<(u32, u32)>,
    /// Near plane in metres: Gaussians closer than this are culled.
    #[arg(long, default_value_t = opengs_splat::DEFAULT_NEAR, value_parser = cli_values::non_negative_f32)]
    near: f32,
}

/// Where an edited map goes.
#[derive(Debug, clap::Args)]
struct OutputArgs {
    /// The new map (.ply); never the input unless --in-place.
    #[arg(long, required_unless_present = "in_place")]
    out: Option<PathBuf>,
    /// Replace the input map (written beside it first, then renamed over it).
    #[arg(long, conflicts_with = "out")]
    in_place: bool,
}

#[derive(Debug, clap::Args)]
struct ListArgs {
    #[command(flatten)]
    source: SourceArgs,
    /// Only the objects of this class.
    #[arg(long)]
    class: Option<String>,
    /// JSON (one object per row, boxes with their axes) instead of the table.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
#[group(id = "prompt", required = true, multiple = false, args = ["pixel", "rect"])]
struct PickArgs {
    #[command(flatten)]
    source: SourceArgs,
    /// Pixel U,V of the view.
    #[arg(long, value_name = "U,V", value_parser = parse_pixel)]
    pixel: Option<(u32, u32)>,
    /// Box X0,Y0,X1,Y1 of the view (pixels, corners included).
    #[arg(long = "box", value_name = "X0,Y0,X1,Y1", value_parser = parse_box)]
    rect: Option<PixelBox>,
    #[command(flatten)]
    view: ViewArgs,
    /// JSON instead of the table.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
struct EditArgs {
    #[command(flatten)]
    source: SourceArgs,
    #[command(flatten)]
    select: SelectArgs,
    #[command(flatten)]
    view: ViewArgs,
    #[command(flatten)]
    output: OutputArgs,
}

#[derive(Debug, clap::Args)]
struct MoveArgs {
    #[command(flatten)]
    edit: EditArgs,
    /// Translation X,Y,Z in metres (world frame).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true, value_parser = parse_vec3)]
    translate: [f64; 3],
}

#[derive(Debug, clap::Args)]
struct RotateArgs {
    #[command(flatten)]
    edit: EditArgs,
    /// Rotation axis X,Y,Z (world frame; any length but zero).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true, value_parser = parse_vec3)]
    axis: [f64; 3],
    /// Angle in degrees (right-hand rule about --axis).
    #[arg(long, allow_hyphen_values = true, value_parser = cli_values::finite)]
    degrees: f64,
    /// Centre of the turn X,Y,Z; default: the selection's opacity-weighted centroid.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true, value_parser = parse_vec3)]
    about: Option<[f64; 3]>,
}

#[derive(Debug, clap::Args)]
struct RenderEditArgs {
    #[command(flatten)]
    source: SourceArgs,
    /// The edited map (the output of extract, remove, move or rotate).
    #[arg(long)]
    after: PathBuf,
    #[command(flatten)]
    select: SelectArgs,
    #[command(flatten)]
    view: ViewArgs,
    /// The PNG to write: colour and labels, before left, after right.
    #[arg(long)]
    out: PathBuf,
    /// Scale the PNG by this factor in (0, 4] (e.g. 0.5 for a small picture).
    #[arg(long, default_value_t = 1.0, value_parser = parse_scale)]
    scale: f32,
}

pub fn run(args: ObjectsArgs) -> anyhow::Result<()> {
    match args.command {
        ObjectsCommand::List(a) => list(a),
        ObjectsCommand::Pick(a) => pick(a),
        ObjectsCommand::Extract(a) => edit(a, Edit::Extract),
        ObjectsCommand::Remove(a) => edit(a, Edit::Remove),
        ObjectsCommand::Move(a) => edit(a.edit, Edit::Move(a.translate)),
        ObjectsCommand::Rotate(a) => edit(
            a.edit,
            Edit::Rotate {
                axis: a.axis,
                degrees: a.degrees,
                about: a.about,
            },
        ),
        ObjectsCommand::RenderEdit(a) => render_edit(a),
    }
}

/// A map read from disk with its class names.
struct Source {
    map_path: PathBuf,
    map: GaussianMap,
    sh_degree: u32,
    catalog: Option<Catalog>,
    read_ms: f64,
}

impl SourceArgs {
    fn load(&self) -> anyhow::Result<Source> {
        let t0 = Instant::now();
        let (map_path, beside) = if self.source.is_dir() {
            (self.source.join("map.ply"), self.source.join("labels.json"))
        } else {
            let dir = self.source.parent().unwrap_or(Path::new("."));
            (self.source.clone(), dir.join("labels.json"))
        };
        let data =
            std::fs::read(&map_path).with_context(|| format!("reading {}", map_path.display()))?;
        let map = parse_map(&data, &map_path, self.strict)?;
        let sh_degree = ply_sh_degree(&data)
            .map_err(anyhow::Error::msg)
            .with_context(|| map_path.display().to_string())?;
        let catalog = match &self.labels {
            Some(path) => Some(Catalog::load(path)?),
            None if beside.is_file() => Some(Catalog::load(&beside)?),
            None => None,
        };
        Ok(Source {
            map_path,
            map,
            sh_degree,
            catalog,
            read_ms: ms_since(t0),
        })
    }
}

impl ViewArgs {
    /// The camera, or an error naming what `purpose` lacks.
    fn camera(&self, purpose: &str) -> anyhow::Result<Camera> {
        let (Some(pose), Some(intrinsics), Some((w, h))) =
            (&self.pose, &self.intrinsics, self.size)
        else {
            bail!("{purpose} needs a view: --pose, --intrinsics and --size (as `opengs render` takes them)");
        };
        let intrinsics = args::parse_intrinsics(intrinsics, w, h)
            .map_err(anyhow::Error::msg)
            .context("--intrinsics")?;
        let pose =
            opengs_geometry::parse_tum_pose(pose).with_context(|| format!("--pose '{pose}'"))?;
        // Before and after, side by side: twice a labelled render.
        args::check_render_size(w.saturating_mul(2), h, None)
            .map_err(anyhow::Error::msg)
            .context("--size")?;
        Ok(Camera::from_pose(intrinsics, &pose, self.near))
    }
}

/// Voted labels (GS Voting) of `map` from `camera`, with what a pixel pick replays.
fn voted_render(map: &GaussianMap, camera: &Camera) -> opengs_splat::Rendered {
    let request = RenderRequest {
        labels: true,
        ..RenderRequest::color_depth()
    };
    render(map, camera, &request)
}

impl SelectArgs {
    fn resolve(&self, source: &Source, view: &ViewArgs) -> anyhow::Result<Selection> {
        let (map, catalog) = (&source.map, source.catalog.as_ref());
        require_labels(map).with_context(|| source.map_path.display().to_string())?;
        let selection = if let Some(class) = &self.class {
            Selection::of_class(map, catalog, class)?
        } else if let Some((u, v)) = self.pixel {
            let rendered = voted_render(map, &view.camera("--pixel")?);
            let picked = pick_pixel(map, &rendered, u, v).context("--pixel")?;
            Selection::of_labels(map, catalog, &[picked.label])?
        } else if let Some(rect) = self.rect {
            let rendered = voted_render(map, &view.camera("--box")?);
            let out = &rendered.output;
            let labels = out.labels.as_deref().unwrap_or(&[]);
            let picked = pick_box(labels, out.width, out.height, rect).context("--box")?;
            Selection::of_labels(map, catalog, &picked.selected().context("--box")?)?
        } else {
            Selection::of_labels(map, catalog, &self.label)?
        };
        Ok(selection)
    }
}

fn list(args: ListArgs) -> anyhow::Result<()> {
    let source = args.source.load()?;
    require_labels(&source.map).with_context(|| source.map_path.display().to_string())?;
    let t0 = Instant::now();
    let mut rows = list_objects(&source.map, source.catalog.as_ref());
    let list_ms = ms_since(t0);
    if let Some(class) = &args.class {
        let selection = Selection::of_class(&source.map, source.catalog.as_ref(), class)?;
        rows.retain(|r| selection.contains(r.id));
    }
    let unlabelled = source.map.labels.iter().filter(|&&l| l == 0).count();
    let summary = format!(
        "{} objects, {} Gaussians ({unlabelled} unlabelled) in {}; classes from {}; read {:.0} ms, listed {:.0} ms",
        rows.len(),
        source.map.len(),
        source.map_path.display(),
        source
            .catalog
            .as_ref()
            .map_or("nowhere (no labels.json)".into(), |c| c.source.display().to_string()),
        source.read_ms,
        list_ms,
    );
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        eprintln!("{summary}");
    } else {
        print!("{}", object_table(&rows));
        println!("{summary}");
    }
    Ok(())
}

fn object_table(rows: &[ObjectSummary]) -> String {
    let mut text = format!(
        "{:>5}  {:<14} {:>5} {:>9} {:>7}  {:<23} {:<23} {:<23} {:<20} {:>9}\n",
        "id",
        "class",
        "score",
        "gaussians",
        "trimmed",
        "centroid (m)",
        "AABB min (m)",
        "AABB max (m)",
        "OBB edges (m)",
        "volume m³"
    );
    let xyz = |v: [f64; 3]| format!("({:6.2},{:6.2},{:6.2})", v[0], v[1], v[2]);
    for r in rows {
        let class = r.class.as_deref().unwrap_or("-");
        let score = r.score.map_or("-".into(), |s| format!("{s:.2}"));
        let extent = match &r.extent {
            Some(e) => {
                let [a, b, c] = e.obb.half_extents.map(|h| 2.0 * h);
                format!(
                    "{:>7}  {:<23} {:<23} {:<23} {:<20} {:>9.4}",
                    e.trimmed,
                    xyz(e.centroid),
                    xyz(e.aabb.min),
                    xyz(e.aabb.max),
                    format!("{a:.2} x {b:.2} x {c:.2}"),
                    e.volume
                )
            }
            None => format!(
                "{:>7}  (every Gaussian too transparent to show)",
                r.gaussians
            ),
        };
        text += &format!(
            "{:>5}  {class:<14} {score:>5} {:>9} {extent}\n",
            r.id, r.gaussians
        );
    }
    text
}

fn pick(args: PickArgs) -> anyhow::Result<()> {
    let source = args.source.load()?;
    let (map, catalog) = (&source.map, source.catalog.as_ref());
    require_labels(map).with_context(|| source.map_path.display().to_string())?;
    let camera = args.view.camera("pick")?;
    let t0 = Instant::now();
    let rendered = voted_render(map, &camera);
    let render_ms = ms_since(t0);
    let class = |l: u32| match l {
        0 => "(unlabelled)".to_string(),
        _ => catalog.and_then(|c| c.class(l)).unwrap_or("-").to_string(),
    };
    if let Some((u, v)) = args.pixel {
        let picked = pick_pixel(map, &rendered, u, v).context("--pixel")?;
        if args.json {
            println!("{}", serde_json::to_string_pretty(&picked)?);
        } else {
            println!(
                "pixel ({u}, {v}): label {} ({}), voting weight {:.3} of the pixel's α {:.3}",
                picked.label,
                class(picked.label),
                picked.weight,
                picked.alpha
            );
            println!("{:>7}  {:<14} {:>7}", "label", "class", "weight");
            for w in &picked.votes {
                println!("{:>7}  {:<14} {:>7.3}", w.label, class(w.label), w.weight);
            }
        }
    } else if let Some(rect) = args.rect {
        let out = &rendered.output;
        let labels = out.labels.as_deref().unwrap_or(&[]);
        let picked = pick_box(labels, out.width, out.height, rect).context("--box")?;
        if args.json {
            println!("{}", serde_json::to_string_pretty(&picked)?);
        } else {
            println!(
                "{:>7}  {:<14} {:>9} {:>9} {:>9}  dominates",
                "label", "class", "pixels", "% of box", "% inside"
            );
            for v in &picked.votes {
                println!(
                    "{:>7}  {:<14} {:>9} {:>9.1} {:>9.1}  {}",
                    v.label,
                    class(v.label),
                    v.pixels_in_box,
                    100.0 * v.share_of_box,
                    100.0 * v.inside,
                    if v.dominates { "yes" } else { "" }
                );
            }
        }
        let selected = picked.selected().context("--box")?;
        let names: Vec<String> = selected
            .iter()
            .map(|&l| format!("{l} ({})", class(l)))
            .collect();
        eprintln!(
            "box {},{},{},{}: {}",
            rect.x0,
            rect.y0,
            rect.x1,
            rect.y1,
            names.join(", ")
        );
    }
    eprintln!("read {:.0} ms, render {render_ms:.0} ms", source.read_ms);
    Ok(())
}

/// What an edit command does with the selection.
#[derive(Debug, Clone, Copy)]
enum Edit {
    Extract,
    Remove,
    Move([f64; 3]),
    Rotate {
        axis: [f64; 3],
        degrees: f64,
        about: Option<[f64; 3]>,
    },
}

impl Edit {
    fn name(&self) -> &'static str {
        match self {
            Edit::Extract => "extract",
            Edit::Remove => "remove",
            Edit::Move(_) => "move",
            Edit::Rotate { .. } => "rotate",
        }
    }
}

fn edit(args: EditArgs, edit: Edit) -> anyhow::Result<()> {
    let source = args.source.load()?;
    refuse_higher_bands(&source.map_path, source.sh_degree, edit.name())?;
    let out = output_path(&args.output, &source.map_path)?;
    let selection = args.select.resolve(&source, &args.view)?;
    let t0 = Instant::now();
    let map = &source.map;
    let (result, what) = match edit {
        Edit::Extract => {
            let (object, _) = split(map, &selection);
            let what = format!("extracted {} Gaussians", object.len());
            (object, what)
        }
        Edit::Remove => {
            let (object, rest) = split(map, &selection);
            let what = format!("removed {} Gaussians, {} left", object.len(), rest.len());
            (rest, what)
        }
        Edit::Move(t) => {
            let motion = RigidMotion::translation(t).context("--translate")?;
            let mut moved = map.clone();
            let n = apply(&mut moved, &selection, &motion);
            (
                moved,
                format!("moved {n} Gaussians by ({}, {}, {}) m", t[0], t[1], t[2]),
            )
        }
        Edit::Rotate {
            axis,
            degrees,
            about,
        } => {
            let pivot = match about {
                Some(p) => p,
                None => selection_centroid(map, &selection)?,
            };
            let motion = RigidMotion::rotation_about(axis, degrees, pivot)
                .context("--axis/--degrees/--about")?;
            let mut turned = map.clone();
            let n = apply(&mut turned, &selection, &motion);
            let what = format!(
                "turned {n} Gaussians by {degrees}° about axis ({}, {}, {}) through ({:.3}, {:.3}, {:.3})",
                axis[0], axis[1], axis[2], pivot[0], pivot[1], pivot[2]
            );
            (turned, what)
        }
    };
    let edit_ms = ms_since(t0);
    let t1 = Instant::now();
    write_map_replacing(&result, &out)?;
    println!(
        "{}: {what} of {} → {} (read {:.0} ms, {} {edit_ms:.0} ms, write {:.0} ms)",
        edit.name(),
        selection.describe(source.catalog.as_ref()),
        out.display(),
        source.read_ms,
        edit.name(),
        ms_since(t1)
    );
    Ok(())
}

/// Opacity-weighted centroid of the selected Gaussians (strays trimmed), as `list` shows it.
fn selection_centroid(map: &GaussianMap, selection: &Selection) -> anyhow::Result<[f64; 3]> {
    let indices: Vec<u32> = (0..map.len() as u32)
        .filter(|&i| selection.contains(map.labels[i as usize]))
        .collect();
    extent_of(map, &indices).map(|e| e.centroid).context(
        "every selected Gaussian is too transparent to have a centroid; give --about X,Y,Z",
    )
}

/// `--out`, refused when it is the input; or the input itself with `--in-place`.
fn output_path(output: &OutputArgs, input: &Path) -> anyhow::Result<PathBuf> {
    let Some(out) = &output.out else {
        return Ok(input.to_path_buf());
    };
    refuse_overwriting(
        out,
        input,
        "the input map; give another path, or --in-place to replace it",
    )?;
    Ok(out.clone())
}

/// Fails when `out` is a directory or names the same file as `input` (`why` says what that is).
fn refuse_overwriting(out: &Path, input: &Path, why: &str) -> anyhow::Result<()> {
    anyhow::ensure!(
        !out.is_dir(),
        "--out {} is a directory; name the file to write",
        out.display()
    );
    let input_real = input
        .canonicalize()
        .with_context(|| input.display().to_string())?;
    let dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let dir_real = dir
        .canonicalize()
        .with_context(|| format!("--out {}: its directory", out.display()))?;
    if out.file_name().map(|n| dir_real.join(n)) == Some(input_real) {
        bail!("--out {} is {why}", out.display());
    }
    Ok(())
}

/// Writes beside `path` first and renames, so a failed write leaves any old file whole.
fn write_map_replacing(map: &GaussianMap, path: &Path) -> anyhow::Result<()> {
    let name = path
        .file_name()
        .with_context(|| format!("--out {} has no file name", path.display()))?;
    let temporary = path.with_file_name(format!(
        ".{}.{}.partial",
        name.to_string_lossy(),
        std::process::id()
    ));
    let written = write_ply_file(map, &temporary)
        .map_err(anyhow::Error::from)
        .and_then(|()| std::fs::rename(&temporary, path).map_err(anyhow::Error::from));
    if written.is_err() {
        std::fs::remove_file(&temporary).ok();
    }
    written.with_context(|| format!("writing {}", path.display()))
}

fn render_edit(args: RenderEditArgs) -> anyhow::Result<()> {
    let source = args.source.load()?;
    let after = load_map(&args.after, args.source.strict).context("--after")?;
    refuse_overwriting(&args.out, &source.map_path, "the map before the edit")?;
    refuse_overwriting(&args.out, &args.after, "the map after the edit (--after)")?;
    let camera = args.view.camera("render-edit")?;
    let selection = args.select.resolve(&source, &args.view)?;
    let t0 = Instant::now();
    let comparison = compare_edit(&source.map, &after, &camera, &selection);
    let render_ms = ms_since(t0);
    let mut image = comparison.image;
    if args.scale != 1.0 {
        let (w, h) = image.dimensions();
        let size = |v: u32| ((v as f32 * args.scale).round() as u32).max(1);
        image = image::imageops::resize(
            &image,
            size(w),
            size(h),
            image::imageops::FilterType::Triangle,
        );
    }
    image
        .save_with_format(&args.out, image::ImageFormat::Png)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let e = &comparison.effect;
    let share = |n: u64| {
        if e.before == 0 {
            0.0
        } else {
            100.0 * n as f64 / e.before as f64
        }
    };
    println!(
        "{}: {} pixels before the edit, {} after; of its former pixels {:.1} % now show another object, \
         {:.1} % unlabelled Gaussians, {:.1} % nothing (α < ½)",
        selection.describe(source.catalog.as_ref()),
        e.before,
        e.after,
        share(e.former_now_other_label),
        share(e.former_now_unlabelled),
        share(e.former_now_empty)
    );
    if !e.former_now_labels.is_empty() {
        let catalog = source.catalog.as_ref();
        let now: Vec<String> = e
            .former_now_labels
            .iter()
            .map(|&(label, n)| {
                let class = catalog.and_then(|c| c.class(label)).unwrap_or("-");
                format!("{label} ({class}) {:.1} %", share(n))
            })
            .collect();
        println!("its former pixels now show: {}", now.join(", "));
    }
    println!(
        "wrote {} (top: colour, bottom: labels; left before, right after; magenta: where it was, yellow: where it is) in {render_ms:.0} ms",
        args.out.display()
    );
    Ok(())
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Comma-separated numbers of a fixed count, named in errors by what they are.
fn numbers<T: std::str::FromStr, const N: usize>(text: &str, what: &str) -> Result<[T; N], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let values: Vec<T> = parts
        .iter()
        .map(|p| {
            p.parse::<T>()
                .map_err(|_| format!("{what} '{text}': '{p}' is not a valid number"))
        })
        .collect::<Result<_, _>>()?;
    values.try_into().map_err(|v: Vec<T>| {
        format!(
            "{what} '{text}' needs {N} comma-separated numbers, got {}",
            v.len()
        )
    })
}

fn parse_pixel(text: &str) -> Result<(u32, u32), String> {
    let [u, v] = numbers::<u32, 2>(text, "pixel U,V")?;
    Ok((u, v))
}

fn parse_box(text: &str) -> Result<PixelBox, String> {
    let [x0, y0, x1, y1] = numbers::<u32, 4>(text, "box X0,Y0,X1,Y1")?;
    Ok(PixelBox { x0, y0, x1, y1 })
}

/// `--scale`: a factor in (0, 4].
fn parse_scale(text: &str) -> Result<f32, String> {
    match cli_values::positive_f32(text) {
        Ok(s) if s <= 4.0 => Ok(s),
        _ => Err(format!("'{text}' is not a scale in (0, 4]")),
    }
}

fn parse_vec3(text: &str) -> Result<[f64; 3], String> {
    let v = numbers::<f64, 3>(text, "X,Y,Z")?;
    if v.iter().all(|x| x.is_finite()) {
        Ok(v)
    } else {
        Err(format!("X,Y,Z '{text}': every value must be finite"))
    }
}
