//! Which segmenter to run, as named on the command line.

use std::fmt;
use std::str::FromStr;

use crate::{
    ClassicSegmenter, GeometrySegmenter, PerceptionError, PriorSegmenter, Segmenter,
    SegmenterOptions, SimulatedSegmenter,
};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum SegmenterKind {
    /// Graph-based colour + depth + normal segmentation, no weights.
    Classic,
    /// Ground-truth instance labels of the dataset ("Ours(Prior)").
    Prior,
    /// SAM ViT encoder/decoder (ONNX).
    Sam,
    /// MobileSAMv2 (ONNX).
    MobileSamV2,
    /// Depth-first object partitioning by local convexity (LCCP-style), no
    /// weights; colour only where geometry is undecided. The default.
    #[default]
    Geometry,
    /// Ground truth with SAM's failure modes (splits, merges, misses, jittered
    /// boundaries, shuffled ids): a reference to measure the consensus with.
    Simulated,
}

impl SegmenterKind {
    /// Index = `kind_id` on the wire: append, never reorder.
    pub const ALL: [SegmenterKind; 6] = [
        Self::Classic,
        Self::Prior,
        Self::Sam,
        Self::MobileSamV2,
        Self::Geometry,
        Self::Simulated,
    ];

    pub fn as_str(&self) -> &'static str {
        match self {
            Self::Classic => "classic",
            Self::Prior => "prior",
            Self::Sam => "sam",
            Self::MobileSamV2 => "mobilesamv2",
            Self::Geometry => "geometry",
            Self::Simulated => "simulated",
        }
    }

    /// Builds the segmenter with default options (model-based kinds fail:
    /// they need model paths, see [`SegmenterKind::create_with`]).
    pub fn create(&self) -> Result<Box<dyn Segmenter>, PerceptionError> {
        self.create_with(&SegmenterOptions::default())
    }

    /// Builds the segmenter; `sam` and `mobilesamv2` load `options.sam_models`
    /// (`mobilesamv2` prompts with the boxes of `options.proposals` when
    /// given). With ensemble models in `options.ensemble`, any kind's masks
    /// get class names from them.
    pub fn create_with(
        &self,
        options: &SegmenterOptions,
    ) -> Result<Box<dyn Segmenter>, PerceptionError> {
        if options.proposals.is_some() && *self != Self::MobileSamV2 {
            return Err(self.unavailable("box proposals (--proposals) are for mobilesamv2"));
        }
        if options.proposals.is_none() && *self == Self::MobileSamV2 {
            // Without its object-aware boxes it would be SAM's grid under another name.
            return Err(self.unavailable(
                "needs its object-aware box model (--proposals); without it, run sam",
            ));
        }
        let segmenter: Box<dyn Segmenter> = match self {
            Self::Classic => Box::new(ClassicSegmenter::new(options.classic)?),
            Self::Prior => Box::new(PriorSegmenter::new()),
            Self::Geometry => Box::new(GeometrySegmenter::new(options.geometry)?),
            Self::Simulated => Box::new(SimulatedSegmenter::new(options.simulated)?),
            Self::Sam | Self::MobileSamV2 => self.create_model_runner(options)?,
        };
        if options.ensemble.any() {
            self.with_ensemble(segmenter, options)
        } else {
            Ok(segmenter)
        }
    }

    #[cfg(feature = "onnx")]
    fn with_ensemble(
        &self,
        segmenter: Box<dyn Segmenter>,
        options: &SegmenterOptions,
    ) -> Result<Box<dyn Segmenter>, PerceptionError> {
        let ensemble = crate::ensemble::Ensemble::new(&options.ensemble, options.threads)?;
        Ok(Box::new(crate::ensemble::EnsembleSegmenter::new(
            segmenter, ensemble,
        )))
    }

    #[cfg(not(feature = "onnx"))]
    fn with_ensemble(
        &self,
        _segmenter: Box<dyn Segmenter>,
        _options: &SegmenterOptions,
    ) -> Result<Box<dyn Segmenter>, PerceptionError> {
        Err(self.unavailable("the tagger/detector ensemble needs the `onnx` cargo feature"))
    }

    #[cfg(feature = "onnx")]
    fn create_model_runner(
        &self,
        options: &SegmenterOptions,
    ) -> Result<Box<dyn Segmenter>, PerceptionError> {
        let paths = options
            .sam_models
            .as_ref()
            .ok_or_else(|| self.unavailable("needs encoder and decoder model paths"))?;
        let mut segmenter = crate::sam::SamSegmenter::new(
            *self,
            paths,
            crate::sam::AmgParams {
                points_per_side: options.points_per_side,
                ..crate::sam::AmgParams::default()
            },
            options.threads,
        )?;
        if let Some(proposals) = &options.proposals {
            let proposer = crate::sam::BoxProposer::new(proposals, options.threads)?;
            segmenter = segmenter.with_box_proposals(proposer);
        }
        Ok(Box::new(segmenter))
    }

    #[cfg(not(feature = "onnx"))]
    fn create_model_runner(
        &self,
        _options: &SegmenterOptions,
    ) -> Result<Box<dyn Segmenter>, PerceptionError> {
        Err(self
            .unavailable("built without the `onnx` cargo feature; use geometry, classic or prior"))
    }

    fn unavailable(&self, reason: &str) -> PerceptionError {
        PerceptionError::Unavailable {
            kind: self.as_str().to_string(),
            reason: reason.to_string(),
        }
    }
}

impl fmt::Display for SegmenterKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for SegmenterKind {
    type Err = PerceptionError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let key: String = s
            .trim()
            .chars()
            .filter(|c| !matches!(c, '-' | '_'))
            .collect::<String>()
            .to_ascii_lowercase();
        match key.as_str() {
            "classic" => Ok(Self::Classic),
            "prior" => Ok(Self::Prior),
            "sam" => Ok(Self::Sam),
            "mobilesamv2" => Ok(Self::MobileSamV2),
            "geometry" => Ok(Self::Geometry),
            "simulated" => Ok(Self::Simulated),
            _ => Err(PerceptionError::UnknownKind(s.to_string())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for kind in SegmenterKind::ALL {
            assert_eq!(kind.to_string().parse::<SegmenterKind>().ok(), Some(kind));
        }
        assert_eq!(
            "Mobile-SAM-v2".parse::<SegmenterKind>().ok(),
            Some(SegmenterKind::MobileSamV2)
        );
        assert!("yolo".parse::<SegmenterKind>().is_err());
        // The wire's kind_id is the index in ALL: the first four never move.
        assert_eq!(SegmenterKind::ALL[3], SegmenterKind::MobileSamV2);
        assert_eq!(SegmenterKind::ALL[4], SegmenterKind::Geometry);
        assert_eq!(SegmenterKind::ALL[5], SegmenterKind::Simulated);
    }
}
