//! Full backward pass of the colour + depth renderer: rasterizer backward over tiles, then
//! the projection chain per Gaussian (both rayon-parallel).

use rayon::prelude::*;

use crate::camera::Camera;
use crate::grads::MapGrads;
use crate::map::GaussianMap;
use crate::project_backward::project_backward;
use crate::raster_backward::RasterBackward;
use crate::render::Rendered;

/// Reusable buffers of the backward pass.
#[derive(Debug, Default)]
pub struct Backward {
    raster: RasterBackward,
}

impl Backward {
    pub fn new() -> Self {
        Self::default()
    }

    /// Gradients of a loss w.r.t. every parameter of `map`, given dL/dC and dL/dD of the
    /// render `rendered` (made from `map` and `camera`). Overwrites `grads`.
    pub fn run(
        &mut self,
        map: &GaussianMap,
        camera: &Camera,
        rendered: &Rendered,
        dl_dcolor: &[[f32; 3]],
        dl_ddepth: &[f32],
        grads: &mut MapGrads,
    ) {
        assert_eq!(
            rendered.projected.len(),
            map.len(),
            "render is not of this map"
        );
        self.raster.run(
            &rendered.projected,
            &rendered.bins,
            &rendered.output,
            dl_dcolor,
            dl_ddepth,
        );
        grads.reset(map.len());
        const CHUNK: usize = 2048;
        let screen = self.raster.drain_chunks(CHUNK);
        grads
            .means
            .par_chunks_mut(CHUNK)
            .zip(grads.rotations.par_chunks_mut(CHUNK))
            .zip(grads.log_scales.par_chunks_mut(CHUNK))
            .zip(grads.opacity_logits.par_chunks_mut(CHUNK))
            .zip(grads.sh_dc.par_chunks_mut(CHUNK))
            .zip(screen.into_par_iter())
            .enumerate()
            .for_each(
                |(c, (((((means, rots), scales), opacities), shs), mut screen))| {
                    for j in 0..means.len() {
                        let i = c * CHUNK + j;
                        // Gaussians that touched no pixel keep zero gradients.
                        let Some(sg) = screen.take_next() else {
                            continue;
                        };
                        let g = project_backward(
                            camera,
                            map.means[i],
                            map.rotations[i],
                            map.log_scales[i],
                            map.opacity_logits[i],
                            map.sh_dc[i],
                            &sg,
                        );
                        means[j] = g.mean;
                        rots[j] = g.rotation;
                        scales[j] = g.log_scale;
                        opacities[j] = g.opacity_logit;
                        shs[j] = g.sh_dc;
                    }
                },
            );
    }
}
