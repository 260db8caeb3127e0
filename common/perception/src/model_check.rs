//! `opengs models check`: does an ONNX file have the input/output names and
//! shapes that its role's runner feeds and reads?
//!
//! Expected signatures (float32 everywhere; `?` = any size; a model may fix
//! a `?` or leave any dimension dynamic; extra outputs are ignored, extra
//! inputs are an error because the runner cannot feed them):
//!
//! | role | inputs | outputs |
//! |---|---|---|
//! | encoder (SAM, MobileSAMv2) | `image[1,3,1024,1024]` | `image_embeddings[1,256,64,64]` |
//! | decoder (SAM export) | `image_embeddings[1,256,64,64]`, `point_coords[1,?,2]`, `point_labels[1,?]`, `mask_input[1,1,256,256]`, `has_mask_input[1]`, `orig_im_size[2]` | `masks[1,?,?,?]`, `iou_predictions[1,?]`, `low_res_masks[1,?,256,256]` |
//! | tagger (RAM/RAM++, recognize-anything export) | `image[1,3,?,?]` (384) | `tag[1,T]` or `logits[1,T]` |
//! | detector (YOLO-World, text-feature prompt) | `images[1,3,?,?]` (640), `text_features[1,K,D]` | `scores[1,N,K]`, `boxes[1,N,4]` |
//! | proposals (MobileSAMv2 object-aware YOLOv8) | `images[1,3,?,?]` | `output0[1,4+nc,N]` |

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use crate::PerceptionError;

/// What a model file is used for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ModelRole {
    Encoder,
    Decoder,
    Tagger,
    Detector,
    Proposals,
}

impl ModelRole {
    pub const ALL: [ModelRole; 5] = [
        Self::Encoder,
        Self::Decoder,
        Self::Tagger,
        Self::Detector,
        Self::Proposals,
    ];

    pub fn as_str(&self) -> &'static str {
        match self {
            Self::Encoder => "encoder",
            Self::Decoder => "decoder",
            Self::Tagger => "tagger",
            Self::Detector => "detector",
            Self::Proposals => "proposals",
        }
    }

    fn spec(&self) -> &'static [(Side, &'static [&'static str], &'static [Dim])] {
        use Dim::{Any, AtLeast, Is};
        use Side::{In, Out};
        match self {
            Self::Encoder => &[
                (In, &["image"], &[Is(1), Is(3), Is(1024), Is(1024)]),
                (
                    Out,
                    &["image_embeddings"],
                    &[Is(1), Is(256), Is(64), Is(64)],
                ),
            ],
            Self::Decoder => &[
                (In, &["image_embeddings"], &[Is(1), Is(256), Is(64), Is(64)]),
                (In, &["point_coords"], &[Is(1), Any, Is(2)]),
                (In, &["point_labels"], &[Is(1), Any]),
                (In, &["mask_input"], &[Is(1), Is(1), Is(256), Is(256)]),
                (In, &["has_mask_input"], &[Is(1)]),
                (In, &["orig_im_size"], &[Is(2)]),
                (Out, &["masks"], &[Is(1), Any, Any, Any]),
                (Out, &["iou_predictions"], &[Is(1), Any]),
                (Out, &["low_res_masks"], &[Is(1), Any, Is(256), Is(256)]),
            ],
            Self::Tagger => &[
                (In, &["image"], &[Is(1), Is(3), Any, Any]),
                (Out, &["tag", "logits"], &[Is(1), Any]),
            ],
            Self::Detector => &[
                (In, &["images"], &[Is(1), Is(3), Any, Any]),
                (In, &["text_features"], &[Is(1), Any, Any]),
                (Out, &["scores"], &[Is(1), Any, Any]),
                (Out, &["boxes"], &[Is(1), Any, Is(4)]),
            ],
            Self::Proposals => &[
                (In, &["images"], &[Is(1), Is(3), Any, Any]),
                (Out, &["output0"], &[Is(1), AtLeast(5), Any]),
            ],
        }
    }

    /// The expected signature in words, e.g. `inputs image[1,3,1024,1024]; outputs ...`.
    pub fn expected(&self) -> String {
        let list = |side: Side| {
            self.spec()
                .iter()
                .filter(|(s, _, _)| *s == side)
                .map(|(_, names, dims)| {
                    let dims: Vec<String> = dims.iter().map(Dim::to_string).collect();
                    format!("{}[{}]", names.join("|"), dims.join(","))
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        format!("inputs {}; outputs {}", list(Side::In), list(Side::Out))
    }
}

impl fmt::Display for ModelRole {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for ModelRole {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let key = s.trim().to_ascii_lowercase();
        Self::ALL
            .into_iter()
            .find(|r| r.as_str() == key)
            .ok_or_else(|| {
                format!("unknown model role '{s}': expected encoder, decoder, tagger, detector or proposals")
            })
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Side {
    In,
    Out,
}

#[derive(Debug, Clone, Copy)]
enum Dim {
    Is(i64),
    AtLeast(i64),
    Any,
}

impl Dim {
    /// A dynamic model dimension (-1) matches anything: it is bound at run time.
    fn accepts(&self, d: i64) -> bool {
        match *self {
            _ if d < 0 => true,
            Dim::Is(n) => d == n,
            Dim::AtLeast(n) => d >= n,
            Dim::Any => true,
        }
    }
}

impl fmt::Display for Dim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Dim::Is(n) => write!(f, "{n}"),
            Dim::AtLeast(n) => write!(f, ">={n}"),
            Dim::Any => f.write_str("?"),
        }
    }
}

/// One model input or output as declared in the file.
#[derive(Debug, Clone, PartialEq)]
pub struct TensorInfo {
    pub name: String,
    /// Declared shape; -1 for a dynamic dimension.
    pub shape: Vec<i64>,
    /// Element type is float32.
    pub float: bool,
}

impl fmt::Display for TensorInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let dims: Vec<String> = self
            .shape
            .iter()
            .map(|d| if *d < 0 { "?".into() } else { d.to_string() })
            .collect();
        write!(f, "{}[{}]", self.name, dims.join(","))?;
        if !self.float {
            f.write_str(" (not float32)")?;
        }
        Ok(())
    }
}

/// The declared inputs and outputs of a model.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Signature {
    pub inputs: Vec<TensorInfo>,
    pub outputs: Vec<TensorInfo>,
}

impl Signature {
    fn found(&self) -> String {
        let list = |v: &[TensorInfo]| {
            v.iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        };
        format!(
            "inputs {}; outputs {}",
            list(&self.inputs),
            list(&self.outputs)
        )
    }

    fn has_input(&self, name: &str) -> bool {
        self.inputs.iter().any(|t| t.name == name)
    }

    fn has_output(&self, name: &str) -> bool {
        self.outputs.iter().any(|t| t.name == name)
    }
}

/// Checks `sig` against `role`; the error lists every problem, then what
/// was expected and what was found.
pub fn check_signature(role: ModelRole, sig: &Signature) -> Result<(), String> {
    let mut problems = Vec::new();
    for (side, names, dims) in role.spec() {
        let (list, what) = match side {
            Side::In => (&sig.inputs, "input"),
            Side::Out => (&sig.outputs, "output"),
        };
        let Some(t) = list.iter().find(|t| names.contains(&t.name.as_str())) else {
            problems.push(format!("no {what} named {}", names.join(" or ")));
            continue;
        };
        let shape_ok =
            t.shape.len() == dims.len() && dims.iter().zip(&t.shape).all(|(d, &n)| d.accepts(n));
        if !shape_ok || !t.float {
            let dims: Vec<String> = dims.iter().map(Dim::to_string).collect();
            problems.push(format!("{what} {t} should be float32 [{}]", dims.join(",")));
        }
    }
    for t in &sig.inputs {
        let known = role
            .spec()
            .iter()
            .any(|(s, names, _)| *s == Side::In && names.contains(&t.name.as_str()));
        if !known {
            problems.push(format!("unexpected input {t}"));
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "does not fit role {role}: {}. Expected {}; found {}",
            problems.join("; "),
            role.expected(),
            sig.found()
        ))
    }
}

/// The role a signature's names point to, if any.
pub fn guess_role(sig: &Signature) -> Option<ModelRole> {
    if sig.has_input("point_coords") {
        Some(ModelRole::Decoder)
    } else if sig.has_output("image_embeddings") {
        Some(ModelRole::Encoder)
    } else if sig.has_input("text_features") {
        Some(ModelRole::Detector)
    } else if sig.has_output("output0") {
        Some(ModelRole::Proposals)
    } else if sig.has_output("tag") || sig.has_output("logits") {
        Some(ModelRole::Tagger)
    } else {
        None
    }
}

/// Outcome of checking one file.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelCheck {
    pub role: ModelRole,
    /// The role came from the names, not from the caller.
    pub guessed: bool,
    pub signature: Signature,
}

/// Loads `path` with ONNX Runtime and checks it against `role` (guessed from
/// the names when `None`).
pub fn check_model(path: &Path, role: Option<ModelRole>) -> Result<ModelCheck, PerceptionError> {
    let signature = read_signature(path)?;
    let model_error = |message: String| PerceptionError::Model {
        path: path.to_path_buf(),
        message,
    };
    let (role, guessed) = match role {
        Some(r) => (r, false),
        None => (
            guess_role(&signature).ok_or_else(|| {
                model_error(format!(
                    "cannot tell its role from its names (found {}); pass --role encoder|decoder|tagger|detector|proposals",
                    signature.found()
                ))
            })?,
            true,
        ),
    };
    check_signature(role, &signature).map_err(model_error)?;
    Ok(ModelCheck {
        role,
        guessed,
        signature,
    })
}

#[cfg(feature = "onnx")]
fn read_signature(path: &Path) -> Result<Signature, PerceptionError> {
    let session = crate::sam::runtime::load_session(path, 1)?;
    Ok(session_signature(&session))
}

#[cfg(not(feature = "onnx"))]
fn read_signature(_path: &Path) -> Result<Signature, PerceptionError> {
    Err(PerceptionError::Unavailable {
        kind: "onnx".into(),
        reason:
            "built without the `onnx` cargo feature (build with --features opengs-perception/onnx)"
                .into(),
    })
}

/// The declared inputs and outputs of a loaded session.
#[cfg(feature = "onnx")]
pub(crate) fn session_signature(session: &ort::session::Session) -> Signature {
    let info = |o: &ort::value::Outlet| TensorInfo {
        name: o.name().to_string(),
        shape: o
            .dtype()
            .tensor_shape()
            .map(|s| s.to_vec())
            .unwrap_or_default(),
        float: o.dtype().tensor_type() == Some(ort::value::TensorElementType::Float32),
    };
    Signature {
        inputs: session.inputs().iter().map(info).collect(),
        outputs: session.outputs().iter().map(info).collect(),
    }
}

/// Loads `path` and fails unless it fits `role` (used by the runners).
#[cfg(feature = "onnx")]
pub(crate) fn load_checked(
    path: &Path,
    role: ModelRole,
    threads: usize,
) -> Result<ort::session::Session, PerceptionError> {
    let session = crate::sam::runtime::load_session(path, threads)?;
    check_signature(role, &session_signature(&session)).map_err(|message| {
        PerceptionError::Model {
            path: path.to_path_buf(),
            message,
        }
    })?;
    Ok(session)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(name: &str, shape: &[i64]) -> TensorInfo {
        TensorInfo {
            name: name.into(),
            shape: shape.to_vec(),
            float: true,
        }
    }

    fn detector() -> Signature {
        Signature {
            inputs: vec![
                t("images", &[1, 3, 640, 640]),
                t("text_features", &[1, -1, 512]),
            ],
            outputs: vec![t("scores", &[1, 8400, -1]), t("boxes", &[1, 8400, 4])],
        }
    }

    #[test]
    fn accepts_the_export_layouts_and_guesses_roles() {
        let sig = detector();
        assert_eq!(check_signature(ModelRole::Detector, &sig), Ok(()));
        assert_eq!(guess_role(&sig), Some(ModelRole::Detector));
        let proposals = Signature {
            inputs: vec![t("images", &[1, 3, 1024, 1024])],
            outputs: vec![
                t("output0", &[1, 5, 21504]),
                t("output1", &[1, 32, 256, 256]),
            ],
        };
        assert_eq!(check_signature(ModelRole::Proposals, &proposals), Ok(()));
        assert_eq!(guess_role(&proposals), Some(ModelRole::Proposals));
        let tagger = Signature {
            inputs: vec![t("image", &[-1, 3, 384, 384])],
            outputs: vec![t("logits", &[-1, 4585])],
        };
        assert_eq!(check_signature(ModelRole::Tagger, &tagger), Ok(()));
        assert_eq!(guess_role(&tagger), Some(ModelRole::Tagger));
    }

    #[test]
    fn wrong_names_shapes_and_types_are_explained() {
        let mut sig = detector();
        sig.inputs[0].name = "img".into();
        let err = check_signature(ModelRole::Detector, &sig).unwrap_err();
        assert!(err.contains("no input named images"), "{err}");
        assert!(err.contains("unexpected input img[1,3,640,640]"), "{err}");
        assert!(
            err.contains("Expected inputs images[1,3,?,?], text_features[1,?,?]"),
            "{err}"
        );
        assert!(err.contains("found inputs img[1,3,640,640]"), "{err}");

        let mut sig = detector();
        sig.outputs[1].shape = vec![1, 8400, 5];
        sig.inputs[1].float = false;
        let err = check_signature(ModelRole::Detector, &sig).unwrap_err();
        assert!(
            err.contains("output boxes[1,8400,5] should be float32 [1,?,4]"),
            "{err}"
        );
        assert!(
            err.contains("text_features[1,?,512] (not float32)"),
            "{err}"
        );

        let err = check_signature(ModelRole::Encoder, &detector()).unwrap_err();
        assert!(err.starts_with("does not fit role encoder"), "{err}");
        assert_eq!(guess_role(&Signature::default()), None);
        assert!("segmenter".parse::<ModelRole>().is_err());
        assert_eq!("Tagger".parse::<ModelRole>(), Ok(ModelRole::Tagger));
    }
}
