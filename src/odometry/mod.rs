//! LiDAR odometry: each frame of one sensor registered to a local map of the frames before it,
//! giving the sensor's poses over a recording.
//!
//! The approach is KISS-ICP's (Vizzo et al., 2023), written here with a point-to-plane
//! registration:
//!
//! 1. **Preprocess**: keep the returns within `[min_range, max_range]`; downsample to half a
//!    map voxel (what the map receives) and that again to 1.5 voxels (what is registered).
//! 2. **Predict** with constant velocity: the last motion applied once more.
//! 3. **Register** the frame to the local map (`registration.rs`): point-to-plane Gauss–Newton,
//!    correspondences within three standard deviations of the prediction's past error
//!    (`threshold.rs`; never below `min_distance`), a Cauchy loss at a third of that.
//! 4. **Update the map** (`voxel_map.rs`): the frame's half-voxel points, with normals estimated
//!    from their ten nearest neighbours in the frame, go into voxels that are not yet full;
//!    voxels beyond `max_range` of the sensor are dropped.
//!
//! Poses are `world_from_sensor` with the world the sensor's first frame, so `poses[0]` is the
//! identity. Everything is deterministic (fixed-order sums, no random choice).
//!
#![cfg_attr(feature = "sim", doc = "```")]
#![cfg_attr(not(feature = "sim"), doc = "```ignore")]
//! use lidarcal::odometry::{odometry, OdometryOptions};
//! use lidarcal::sim::{scan, BeamModel, Preset, ScanOptions};
//! use lidarcal::sim::scenes::{street_scene, StreetOptions};
//! use nalgebra::Isometry3;
//!
//! // A roof HDL-64E driving 0.5 m per frame down the simulated street.
//! let street = street_scene(&StreetOptions::default())?;
//! let model = BeamModel::preset(Preset::Hdl64e);
//! let start = street.world_from_reference;
//! let frames = (0..6)
//!     .map(|k| {
//!         let pose = start * Isometry3::translation(0.5 * k as f64, 0.0, 0.0);
//!         let options = ScanOptions { seed: k, ..ScanOptions::default() };
//!         Ok(scan(&model, &street.shapes, &pose, &options)?.positions())
//!     })
//!     .collect::<lidarcal::Result<Vec<_>>>()?;
//! let result = odometry(&frames, &OdometryOptions::default())?;
//! let last = result.poses[5].translation.vector;
//! assert!((last.x - 2.5).abs() < 0.05 && last.y.abs() < 0.05 && last.z.abs() < 0.05);
//! # Ok::<(), lidarcal::Error>(())
//! ```

mod registration;
mod threshold;
mod voxel_map;

use nalgebra::{Isometry3, Point3, Vector3};

use crate::error::{ensure_finite, Error, FailureKind, Result};
use crate::fit::Moments;
use crate::geometry::cell_key;
use crate::grid::NeighbourGrid;
use crate::icp::weakest_directions;
use registration::register;
use rustc_hash::FxHashSet;
use threshold::AdaptiveThreshold;
use voxel_map::{MapPoint, VoxelMap};

/// Fewest points a frame must keep after the range crop and the half-voxel downsampling.
pub const MIN_FRAME_POINTS: usize = 50;

/// Options of [`odometry`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryOptions {
    /// Side of the map's voxels (metres). The frames are downsampled to half of it for the map
    /// and to 1.5 times it for the registration. Default 1.0 (KISS-ICP's choice for a 100 m
    /// sensor).
    pub voxel: f64,
    /// Points a map voxel holds at most. Default 20.
    pub max_points_per_voxel: usize,
    /// Returns nearer than this are dropped (metres; the vehicle's own body). Default 0.5.
    pub min_range: f64,
    /// Returns farther than this are dropped, and map voxels farther from the sensor (metres).
    /// Default 100.
    pub max_range: f64,
    /// Correspondence scale (metres, one standard deviation) before any motion has been
    /// measured. Default 2.0.
    pub initial_threshold: f64,
    /// Smallest correspondence distance (metres): the map's points lie up to about half a voxel
    /// apart, so a distance below that would lose true correspondences. Default 0.5.
    pub min_distance: f64,
    /// A frame whose motion moves no point within `max_range` by more than this (metres) does
    /// not update the adaptive threshold. Default 0.1.
    pub min_motion: f64,
    /// Gauss–Newton iterations per frame at most. Default 50.
    pub max_iterations: usize,
    /// A frame's registration stops when a step is below this (tangent norm). Default 1e-4.
    pub tolerance: f64,
}

impl Default for OdometryOptions {
    fn default() -> Self {
        OdometryOptions {
            voxel: 1.0,
            max_points_per_voxel: 20,
            min_range: 0.5,
            max_range: 100.0,
            initial_threshold: 2.0,
            min_distance: 0.5,
            min_motion: 0.1,
            max_iterations: 50,
            tolerance: 1e-4,
        }
    }
}

impl OdometryOptions {
    /// Checks every option's range.
    pub fn validate(&self) -> Result<()> {
        let positive = [
            ("voxel", self.voxel),
            ("max_range", self.max_range),
            ("initial_threshold", self.initial_threshold),
            ("min_distance", self.min_distance),
            ("tolerance", self.tolerance),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(Error::InvalidInput(format!(
                    "odometry option {name} must be finite and positive, got {value}"
                )));
            }
        }
        if !(self.min_range.is_finite() && self.min_range >= 0.0 && self.min_range < self.max_range)
        {
            return Err(Error::InvalidInput(format!(
                "odometry option min_range must be in [0, max_range = {}), got {}",
                self.max_range, self.min_range
            )));
        }
        if !(self.min_motion.is_finite() && self.min_motion >= 0.0) {
            return Err(Error::InvalidInput(format!(
                "odometry option min_motion must be finite and >= 0, got {}",
                self.min_motion
            )));
        }
        if self.max_points_per_voxel == 0 || self.max_iterations == 0 {
            return Err(Error::InvalidInput(
                "odometry options max_points_per_voxel and max_iterations must be >= 1".into(),
            ));
        }
        Ok(())
    }
}

/// How one frame's registration went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameReport {
    /// Gauss–Newton iterations (0 for the first frame).
    pub iterations: usize,
    /// Whether the last step was below the tolerance.
    pub converged: bool,
    /// Source points with a map correspondence at the end.
    pub correspondences: usize,
    /// Source points registered (after the 1.5-voxel downsampling).
    pub source_points: usize,
    /// Root-mean-square point-to-plane residual of the correspondences (metres).
    pub rmse: f64,
    /// Correspondence distance used (metres).
    pub distance: f64,
    /// The least-constrained translation direction (world frame) and its share of the
    /// translation information (`1/3` isotropic, near 0 along a featureless corridor).
    pub weakest_translation: (Vector3<f64>, f64),
}

/// The poses of one sensor over a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// `world_from_sensor` per frame; the world is the first frame, so `poses[0]` is the identity.
    pub poses: Vec<Isometry3<f64>>,
    /// One report per frame.
    pub frames: Vec<FrameReport>,
    /// Length of the path the sensor travelled (metres).
    pub distance: f64,
}

/// The frame's returns within the range limits.
fn crop(frame: &[Point3<f64>], options: &OdometryOptions) -> Vec<Point3<f64>> {
    let (lo, hi) = (options.min_range.powi(2), options.max_range.powi(2));
    frame
        .iter()
        .copied()
        .filter(|p| (lo..=hi).contains(&p.coords.norm_squared()))
        .collect()
}

/// The first point of each cubic voxel of side `voxel`, in input order: unlike a centroid, it
/// lies on the surface it was measured on, also where a voxel spans an edge (KISS-ICP keeps the
/// first point too).
fn first_per_voxel(points: &[Point3<f64>], voxel: f64) -> Vec<Point3<f64>> {
    let mut seen: FxHashSet<[i64; 3]> = FxHashSet::default();
    points
        .iter()
        .filter(|p| seen.insert(cell_key(&p.coords, voxel)))
        .copied()
        .collect()
}

/// Smallest correspondence distance of a frame's coarse pass, in voxels.
const COARSE_FLOOR_VOXELS: f64 = 2.0;

/// Neighbours a map point's normal is estimated from.
const NORMAL_NEIGHBOURS: usize = 10;
/// Largest surface variation `l0 / (l0 + l1 + l2)` of a neighbourhood that counts as a surface.
const MAX_SURFACE_VARIATION: f64 = 0.08;
/// Smallest share `l1 / (l0 + l1 + l2)` of the middle axis: below it the neighbourhood is a
/// line (one scan ring far away), whose normal could be any direction across it.
const MIN_SPREAD: f64 = 0.05;

/// The map points of a frame registered at `pose`: its half-voxel points whose ten nearest
/// neighbours within one voxel form a surface, with that surface's normal.
fn map_points(points: &[Point3<f64>], pose: &Isometry3<f64>, voxel: f64) -> Vec<MapPoint> {
    let grid = NeighbourGrid::new(points, voxel);
    points
        .iter()
        .filter_map(|p| {
            let near = grid.nearest_k(p, NORMAL_NEIGHBOURS, voxel)?;
            let mut m = Moments::new(*p);
            for (i, _) in near {
                m.add(points.get(i)?);
            }
            let (values, vectors) = m.principal_axes();
            let total = values[0] + values[1] + values[2];
            let surface = total > 0.0
                && values[0] <= MAX_SURFACE_VARIATION * total
                && values[1] >= MIN_SPREAD * total;
            surface.then(|| MapPoint {
                position: pose * p,
                normal: pose.rotation * vectors[0],
            })
        })
        .collect()
}

/// The poses of a sensor over `frames` (each in the sensor's frame, in time order, at a steady
/// rate); see the module docs.
///
/// Errors: [`Error::InvalidInput`] for bad options, fewer than two frames, non-finite points or
/// a frame with fewer than [`MIN_FRAME_POINTS`] points after cropping and downsampling (the
/// message names the frame); [`Error::Calibration`] of kind
/// [`NoAgreement`](FailureKind::NoAgreement) when a frame finds no correspondence in the map
/// (the odometry lost track: a jump, or an empty scene).
pub fn odometry(frames: &[Vec<Point3<f64>>], options: &OdometryOptions) -> Result<Odometry> {
    options.validate()?;
    if frames.len() < 2 {
        return Err(Error::InvalidInput(format!(
            "odometry needs at least 2 frames, got {}",
            frames.len()
        )));
    }
    for (k, frame) in frames.iter().enumerate() {
        ensure_finite(
            &format!("frame {k}"),
            frame.iter().flat_map(|p| p.coords.iter()),
        )?;
    }
    let mut map = VoxelMap::new(options.voxel, options.max_points_per_voxel);
    let mut threshold = AdaptiveThreshold::new(
        options.initial_threshold,
        options.min_motion,
        options.max_range,
    );
    let mut poses: Vec<Isometry3<f64>> = Vec::with_capacity(frames.len());
    let mut reports = Vec::with_capacity(frames.len());
    let mut distance = 0.0;
    for (k, frame) in frames.iter().enumerate() {
        let cropped = crop(frame, options);
        let fine = first_per_voxel(&cropped, 0.5 * options.voxel);
        if fine.len() < MIN_FRAME_POINTS {
            return Err(Error::InvalidInput(format!(
                "frame {k} has {} points after the range crop ({}-{} m) and {} m downsampling; \
                 odometry needs at least {MIN_FRAME_POINTS}",
                fine.len(),
                options.min_range,
                options.max_range,
                0.5 * options.voxel
            )));
        }
        let source = first_per_voxel(&fine, 1.5 * options.voxel);
        let (pose, report) = match (poses.last(), poses.len().checked_sub(2)) {
            (None, _) => (
                Isometry3::identity(),
                FrameReport {
                    iterations: 0,
                    converged: true,
                    correspondences: 0,
                    source_points: source.len(),
                    rmse: 0.0,
                    distance: 0.0,
                    weakest_translation: (Vector3::z(), 1.0 / 3.0),
                },
            ),
            (Some(last), before) => {
                let motion = before
                    .and_then(|i| poses.get(i))
                    .map_or(Isometry3::identity(), |b| b.inverse() * last);
                let prediction = last * motion;
                // The coarse pass reaches at least two voxels: after a straight stretch the
                // threshold is a few decimetres, and the first frame of a turn moves points
                // at 30 m by 1-2 m from the prediction (measured on the simulated drives:
                // with the threshold alone the rear unit's odometry slid 1.6 m there).
                let sigma = threshold
                    .sigma()
                    .max(options.min_distance / 3.0)
                    .max(COARSE_FLOOR_VOXELS * options.voxel / 3.0);
                let corr = 3.0 * sigma;
                let reg = register(
                    &map,
                    &source,
                    &prediction,
                    corr,
                    sigma / 3.0,
                    options.max_iterations,
                    options.tolerance,
                )
                .ok_or_else(|| {
                    Error::calibration(
                        FailureKind::NoAgreement,
                        format!(
                            "odometry lost track at frame {k}: fewer than 6 of its {} points \
                             lie within {corr:.2} m of the map built from the frames before",
                            source.len()
                        ),
                    )
                })?;
                // A second pass at the smallest distance: while the threshold is still large
                // (the first frames) the wide kernel leaves the pose a few tenths of a degree
                // off, and the fine pass removes that at the cost of two or three iterations.
                let reg = if corr > options.min_distance {
                    register(
                        &map,
                        &source,
                        &reg.pose,
                        options.min_distance,
                        options.min_distance / 9.0,
                        options.max_iterations,
                        options.tolerance,
                    )
                    .unwrap_or(reg)
                } else {
                    reg
                };
                threshold.update(
                    &(prediction.inverse() * reg.pose),
                    &(last.inverse() * reg.pose),
                );
                distance += (reg.pose.translation.vector - last.translation.vector).norm();
                let report = FrameReport {
                    iterations: reg.iterations,
                    converged: reg.converged,
                    correspondences: reg.correspondences,
                    source_points: source.len(),
                    rmse: reg.rmse,
                    distance: corr,
                    weakest_translation: weakest_directions(&reg.information)[0],
                };
                // Renormalized: the prediction multiplies a pose by the inverse of another (a
                // conjugate, exact only for unit quaternions), so rounding would otherwise
                // compound from frame to frame (measured: a 1e-16 error became a wrong
                // rotation after 40 frames).
                let mut pose = reg.pose;
                pose.rotation.renormalize();
                (pose, report)
            }
        };
        map.add(map_points(&fine, &pose, options.voxel));
        map.retain_within(&Point3::from(pose.translation.vector), options.max_range);
        poses.push(pose);
        reports.push(report);
    }
    Ok(Odometry {
        poses,
        frames: reports,
        distance,
    })
}
