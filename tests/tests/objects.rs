//! `opengs objects` end to end on a hand-built map: list, pick, extract, remove, rotate,
//! render-edit, and the refusals (each names what is wrong, and nothing is written).

use std::path::Path;
use std::process::Output;

use opengs_e2e::binary;
use opengs_splat::{read_ply_file, write_ply_file, Gaussian, GaussianMap};

/// Camera at the origin looking along +z; 64×48, f = 100 px, principal point on pixel (32, 24).
const VIEW: [&str; 6] = [
    "--pose",
    "0 0 0 0 0 0 1",
    "--intrinsics",
    "100 100 32 24",
    "--size",
    "64x48",
];

/// A wall (label 1, 200 Gaussians) at z = 3 over the image's upper two thirds, a cube (label 2,
/// 27 Gaussians) in front of it around (0.5, 0, 2), i.e. pixel (57, 24), and 10 unlabelled
/// Gaussians behind the wall; the bottom-left corner of the view shows nothing.
fn scene() -> GaussianMap {
    let mut map = GaussianMap::new();
    let flat = [1.0, 0.0, 0.0, 0.0];
    for i in 0..20 {
        for j in 0..10 {
            let p = [(i as f32 - 9.5) * 0.1, (j as f32 - 7.0) * 0.1, 3.0];
            map.push(Gaussian::from_values(
                p,
                flat,
                [0.06, 0.06, 0.005],
                0.95,
                [0.6; 3],
                1,
            ));
        }
    }
    for k in 0..27 {
        let p = [
            0.45 + 0.05 * (k % 3) as f32,
            -0.05 + 0.05 * (k / 3 % 3) as f32,
            1.95 + 0.05 * (k / 9) as f32,
        ];
        map.push(Gaussian::from_values(
            p,
            flat,
            [0.03; 3],
            0.9,
            [0.9, 0.1, 0.1],
            2,
        ));
    }
    for k in 0..10 {
        map.push(Gaussian::from_values(
            [k as f32 * 0.1, 0.0, 4.0],
            flat,
            [0.02; 3],
            0.5,
            [0.2; 3],
            0,
        ));
    }
    map
}

const LABELS_JSON: &str = r#"[
  {"id": 1, "class": "wall", "score": 1.0, "confidence": 1.0, "gaussians": 200},
  {"id": 2, "class": "cube", "score": 0.8, "confidence": 0.9, "gaussians": 27}
]"#;

/// A directory shaped like a run's: map.ply and labels.json.
fn run_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    write_ply_file(&scene(), dir.path().join("map.ply")).expect("write map");
    std::fs::write(dir.path().join("labels.json"), LABELS_JSON).expect("write labels");
    dir
}

fn objects(args: &[&str]) -> Output {
    std::process::Command::new(binary("opengs"))
        .arg("objects")
        .args(args)
        .output()
        .expect("opengs runs")
}

/// A temporary path as an argument (temp dirs are UTF-8 here).
fn arg(path: &Path) -> &str {
    path.to_str().expect("UTF-8 temporary path")
}

fn stdout(out: &Output) -> String {
    assert!(
        out.status.success(),
        "failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Fails, with `needle` in its message, and leaves `unwritten` absent.
fn refused(out: &Output, needle: &str, unwritten: &Path) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "should fail with '{needle}'");
    assert!(err.contains(needle), "expected '{needle}' in: {err}");
    assert!(
        !unwritten.exists(),
        "{} written on error",
        unwritten.display()
    );
}

#[test]
fn list_pick_extract_and_remove_on_a_run_directory() {
    let dir = run_dir();
    let run = arg(dir.path());
    let rows: serde_json::Value =
        serde_json::from_str(&stdout(&objects(&["list", run, "--json"]))).expect("JSON");
    let rows = rows.as_array().expect("rows");
    let row = |r: &serde_json::Value| {
        (
            r["id"].as_u64(),
            r["class"].as_str().map(String::from),
            r["gaussians"].as_u64(),
        )
    };
    assert_eq!(rows.len(), 2);
    assert_eq!(row(&rows[0]), (Some(1), Some("wall".into()), Some(200)));
    assert_eq!(row(&rows[1]), (Some(2), Some("cube".into()), Some(27)));
    let aabb = &rows[1]["extent"]["aabb"];
    for (k, (lo, hi)) in [(0.45, 0.55), (-0.05, 0.05), (1.95, 2.05)]
        .into_iter()
        .enumerate()
    {
        assert!(
            (aabb["min"][k].as_f64().expect("number") - lo).abs() < 1e-6,
            "{aabb}"
        );
        assert!(
            (aabb["max"][k].as_f64().expect("number") - hi).abs() < 1e-6,
            "{aabb}"
        );
    }
    let cubes = stdout(&objects(&["list", run, "--class", "Cube"]));
    assert!(cubes.contains("cube") && !cubes.contains("wall"), "{cubes}");

    let picked = stdout(&objects(
        &[&["pick", run, "--pixel", "57,24", "--json"][..], &VIEW].concat(),
    ));
    let picked: serde_json::Value = serde_json::from_str(&picked).expect("JSON");
    assert_eq!(picked["label"].as_u64(), Some(2));
    assert!(picked["weight"].as_f64().expect("weight") > 0.9, "{picked}");

    let object = dir.path().join("cube.ply");
    stdout(&objects(
        &[
            &["extract", run, "--pixel", "57,24", "--out", arg(&object)][..],
            &VIEW,
        ]
        .concat(),
    ));
    let cube = read_ply_file(&object).expect("extracted map");
    assert_eq!(
        (cube.len(), cube.labels.iter().all(|&l| l == 2)),
        (27, true)
    );

    let rest = dir.path().join("no_cube.ply");
    stdout(&objects(&[
        "remove",
        run,
        "--class",
        "cube",
        "--out",
        arg(&rest),
    ]));
    let map = read_ply_file(&rest).expect("edited map");
    assert_eq!(map.len(), 210);
    assert!(map.labels.iter().all(|&l| l != 2));
    // The input is untouched.
    assert_eq!(
        read_ply_file(dir.path().join("map.ply"))
            .expect("input")
            .len(),
        237
    );

    let png = dir.path().join("compare.png");
    let edit = [
        "render-edit",
        run,
        "--label",
        "2",
        "--after",
        arg(&rest),
        "--out",
        arg(&png),
    ];
    let said = stdout(&objects(&[&edit[..], &VIEW].concat()));
    assert!(said.contains("0 after"), "{said}");
    assert_eq!(image_size(&png), (2 * 64 + 4, 2 * 48 + 4));
}

fn image_size(path: &Path) -> (u32, u32) {
    let data = std::fs::read(path).expect("PNG written");
    // PNG: 8-byte signature, IHDR length and type, then width and height big-endian.
    assert_eq!(&data[1..4], b"PNG");
    let be = |o: usize| u32::from_be_bytes([data[o], data[o + 1], data[o + 2], data[o + 3]]);
    (be(16), be(20))
}

#[test]
fn render_edit_needs_a_view() {
    let dir = run_dir();
    let (run, png) = (arg(dir.path()), dir.path().join("compare.png"));
    let map = dir.path().join("map.ply");
    let out = objects(&[
        "render-edit",
        run,
        "--label",
        "2",
        "--after",
        arg(&map),
        "--out",
        arg(&png),
    ]);
    refused(&out, "needs a view: --pose, --intrinsics and --size", &png);
}

#[test]
fn bad_input_is_named_and_nothing_is_written() {
    let dir = run_dir();
    let run = arg(dir.path());
    let out = dir.path().join("out.ply");
    let remove =
        |what: &[&str]| objects(&[&["remove", run, "--out", arg(&out)][..], what].concat());
    refused(
        &remove(&["--label", "99"]),
        "label 99 is not a label of the map",
        &out,
    );
    refused(
        &remove(&["--class", "sofa"]),
        "class 'sofa' is not in",
        &out,
    );
    refused(&remove(&["--label", "0"]), "background", &out);
    refused(
        &remove(&[&["--pixel", "64,10"][..], &VIEW].concat()),
        "pixel (64, 10) is outside the 64x48 image",
        &out,
    );
    refused(
        &remove(&[&["--pixel", "5,45"][..], &VIEW].concat()),
        "no labelled Gaussian at pixel (5, 45)",
        &out,
    );
    refused(
        &remove(&[&["--box", "0,42,3,47"][..], &VIEW].concat()),
        "no label dominates box 0,42,3,47",
        &out,
    );

    // --out may not be the input; --in-place replaces it, leaving no temporary file.
    let input = dir.path().join("map.ply");
    let before = std::fs::read(&input).expect("map");
    let same = dir.path().join(".").join("map.ply");
    let err = objects(&["remove", run, "--label", "2", "--out", arg(&same)]);
    assert!(
        !err.status.success() && String::from_utf8_lossy(&err.stderr).contains("is the input map")
    );
    assert_eq!(std::fs::read(&input).expect("map"), before);
    stdout(&objects(&["remove", run, "--label", "2", "--in-place"]));
    assert_eq!(read_ply_file(&input).expect("replaced").len(), 210);
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .expect("dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.contains("partial")), "{names:?}");

    // A map without labels, and one with SH degree 3 colour (rotation refused, and why).
    let mut unlabelled = scene();
    unlabelled.labels.iter_mut().for_each(|l| *l = 0);
    let bare = dir.path().join("bare.ply");
    write_ply_file(&unlabelled, &bare).expect("write");
    refused(&objects(&["list", arg(&bare)]), "has no labels", &out);
    let sh3 = dir.path().join("sh3.ply");
    std::fs::write(&sh3, sh3_ply()).expect("write");
    let rotate = [
        "rotate",
        arg(&sh3),
        "--label",
        "4",
        "--axis",
        "0,0,1",
        "--degrees",
        "90",
        "--out",
        arg(&out),
    ];
    refused(&objects(&rotate), "SH degree 3", &out);
}
/// One Gaussian of label 4 with 45 `f_rest` values (SH degree 3), ASCII.
fn sh3_ply() -> String {
    let mut text = String::from("ply\nformat ascii 1.0\nelement vertex 1\n");
    let names = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"];
    let rest: Vec<String> = (0..45).map(|i| format!("f_rest_{i}")).collect();
    let tail = [
        "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ];
    for name in names
        .iter()
        .map(|s| s.to_string())
        .chain(rest)
        .chain(tail.iter().map(|s| s.to_string()))
    {
        text += &format!("property float {name}\n");
    }
    text += "property uint label\nend_header\n";
    text += &format!(
        "0 0 2 0.1 0.1 0.1 {} 2 -3 -3 -3 1 0 0 0 4\n",
        vec!["0"; 45].join(" ")
    );
    text
}
