//! `opengs models check` on the perception crate's tiny ONNX fixtures: a
//! misnamed input fails with the expected signature in the message; the
//! real layouts pass. Needs the `onnx` feature and ORT_DYLIB_PATH (as
//! `scripts/test.sh` sets up); says why and passes otherwise.

use std::path::PathBuf;
use std::process::Command;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../common/perception/tests/fixtures")
        .join(name)
}

fn opengs(args: &[&str], files: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_opengs"))
        .arg("models")
        .arg("check")
        .args(files.iter().map(|f| fixture(f)))
        .args(args)
        .output()
        .expect("run opengs");
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success(), text)
}

#[test]
fn models_check_rejects_wrong_input_names() {
    let (ok, text) = opengs(&["--role", "tagger"], &["tiny_tagger_wrong_input.onnx"]);
    assert!(!ok, "{text}");
    if text.contains("unavailable") && std::env::var_os("OPENGS_REQUIRE_ORT").is_none() {
        eprintln!("skipped: {text}");
        return;
    }
    assert!(text.contains("no input named image"), "{text}");
    assert!(text.contains("Expected inputs image[1,3,?,?]"), "{text}");
    let (ok, text) = opengs(
        &[],
        &[
            "tiny_sam_encoder.onnx",
            "tiny_sam_decoder.onnx",
            "tiny_tagger.onnx",
            "tiny_detector.onnx",
            "tiny_proposals.onnx",
        ],
    );
    assert!(ok, "{text}");
    assert_eq!(text.matches("guessed from its names").count(), 5, "{text}");
    let (ok, text) = opengs(&["--role", "segmenter"], &["tiny_tagger.onnx"]);
    assert!(!ok && text.contains("unknown model role"), "{text}");
}
