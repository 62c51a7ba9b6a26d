//! One cloud of a [`PreparedPair`](super::PreparedPair): downsampled, indexed and binned.

use std::sync::Arc;

use nalgebra::Point3;

use super::{CheckOptions, THICKNESS_SAMPLES};
use crate::error::Result;
use crate::icp::{voxel_centroids, SurfaceCloud};
use crate::visibility::RangeImage;

/// What one side of a check starts from besides the cloud itself: nothing (the cloud is
/// downsampled into voxels of [`CheckOptions::voxel_size`]), or a method's own voxels of that
/// size, made by the same downsampling ([`voxel_downsample`](crate::icp::voxel_downsample)),
/// as points or already indexed. The check is the same either way; it skips the work done.
#[derive(Debug, Clone)]
pub(crate) enum Voxels<'a> {
    /// Downsample the cloud.
    Raw,
    /// These are the cloud's voxels.
    Centroids(&'a [Point3<f64>]),
    /// This indexes the cloud's voxels.
    Surface(Arc<SurfaceCloud>),
}

/// One cloud, downsampled and indexed, with its sensor's range image.
#[derive(Debug)]
pub(super) struct Side {
    pub(super) surface: Arc<SurfaceCloud>,
    pub(super) samples: Vec<Point3<f64>>,
    pub(super) image: RangeImage,
}

impl Side {
    /// The median local thickness of the sampled points that lie on a surface (metres; 0 when
    /// none does).
    pub(super) fn thickness(&self) -> f64 {
        let n = self.surface.points().len();
        let samples: Vec<usize> = (0..n)
            .step_by(n.div_ceil(THICKNESS_SAMPLES).max(1))
            .collect();
        // Each sample is independent: in parallel (a millisecond or two of a check's
        // preparation on a 75k-voxel scan).
        let mut values: Vec<f64> = crate::par_map(&samples, |&i| self.surface.thickness(i))
            .into_iter()
            .flatten()
            .collect();
        median(&mut values)
    }

    pub(super) fn new(
        points: &[Point3<f64>],
        voxels: Voxels<'_>,
        options: &CheckOptions,
    ) -> Result<Self> {
        let (indexed, image) = crate::join(
            || -> Result<_> {
                let surface = match voxels {
                    Voxels::Raw => Arc::new(SurfaceCloud::new(voxel_centroids(
                        points,
                        options.voxel_size,
                    )?)?),
                    Voxels::Centroids(v) => Arc::new(SurfaceCloud::new(v.to_vec())?),
                    Voxels::Surface(s) => s,
                };
                let voxels = surface.points();
                let stride = voxels.len().div_ceil(options.samples).max(1);
                let samples = voxels.iter().step_by(stride).copied().collect();
                Ok((surface, samples))
            },
            || RangeImage::new(points, options.visibility_resolution),
        );
        let ((surface, samples), image) = (indexed?, image?);
        Ok(Side {
            surface,
            samples,
            image,
        })
    }
}

/// The median of `values` (0 for none).
fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mid = values.len() / 2;
    let (_, m, _) = values.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    *m
}
