//! Map alignment: the extrinsic that puts the target's frames onto the map the reference built,
//! both placed by the reference's odometry.
//!
//! Hand-eye calibration ([`hand_eye`](fn@super::hand_eye)) leaves the extrinsic a tenth of a degree and a few
//! centimetres off with realistic odometry noise, and the height unobserved on flat ground. The
//! two sensors do see the same facades, poles and cars, at different times: as the vehicle
//! passes, what the front unit saw, the rear one sees a second or two later. So:
//!
//! 1. **The reference map**: every reference frame placed by its odometry pose, downsampled to
//!    voxels in which **the latest frame wins**. The rear unit sees a place soon after the front
//!    one last saw it, so the map's points come from the reference frames nearest in time to
//!    the target's view, and the odometry error between the two views (what the alignment cannot
//!    see) stays that of a few metres of travel instead of the whole drive.
//! 2. **The target's samples**: each target frame downsampled, kept with its frame index.
//! 3. **Point-to-plane Gauss–Newton over the extrinsic alone**: target point `p` of frame `k`
//!    lands at `w = P_k X p` (`P_k` the reference's pose); its residual is `n . (w - m)` against
//!    the nearest map point `m` with normal `n`, under a Cauchy loss at a third of the
//!    correspondence distance, which shrinks geometrically as in [`crate::icp`]. With the left
//!    perturbation `X <- exp(delta) X` and `q = X p`, `n_k = R_k^T n`, the Jacobian row is
//!    `[n_k, q x n_k]`.
//!
//! The information matrix `J^T W J` says which directions the shared views constrain: the
//! height is observed when the ground is in both sensors' frames, and not when it is not.

use nalgebra::{Isometry3, Matrix6, Point3};
use rustc_hash::FxHashMap;

use crate::error::{Error, FailureKind, Result};
use crate::geometry::{cell_key, se3_exp};
use crate::icp::{PlaneSums, SurfaceCloud};
use crate::lm::{accumulate, Loss};

/// Ridge added to `J^T W J` relative to its largest diagonal entry, so an unobserved direction
/// stays where the start put it instead of making the step singular.
const RIDGE: f64 = 1e-9;
/// Fewest correspondences a step is taken from.
const MIN_CORRESPONDENCES: usize = 100;

/// Options of the map alignment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlignOptions {
    /// Voxel of the reference map (metres). Default 0.2.
    pub map_voxel: f64,
    /// Voxel the target frames are downsampled to (metres). Default 0.5.
    pub sample_voxel: f64,
    /// Every `frame_stride`-th target frame is used. Default 1.
    pub frame_stride: usize,
    /// Correspondence distance of the first iteration (metres). Default 1.0.
    pub max_distance: f64,
    /// Correspondence distance it shrinks to (metres). Default 0.2.
    pub min_distance: f64,
    /// Factor applied to the distance after each iteration. Default 0.7.
    pub shrink: f64,
    /// Iterations at most. Default 40.
    pub max_iterations: usize,
    /// Stop once at `min_distance` and a step is below this (tangent norm). Default 1e-5.
    pub tolerance: f64,
}

impl Default for AlignOptions {
    fn default() -> Self {
        AlignOptions {
            map_voxel: 0.2,
            sample_voxel: 0.5,
            frame_stride: 1,
            max_distance: 1.0,
            min_distance: 0.2,
            shrink: 0.7,
            max_iterations: 40,
            tolerance: 1e-5,
        }
    }
}

impl AlignOptions {
    /// Checks every option's range.
    pub fn validate(&self) -> Result<()> {
        let ok = [
            self.map_voxel,
            self.sample_voxel,
            self.min_distance,
            self.tolerance,
        ]
        .iter()
        .all(|v| v.is_finite() && *v > 0.0)
            && self.max_distance.is_finite()
            && self.max_distance >= self.min_distance
            && self.shrink > 0.0
            && self.shrink <= 1.0
            && self.frame_stride >= 1
            && self.max_iterations >= 1;
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidInput(format!(
                "map alignment options out of range: need positive voxels and tolerance, \
                 0 < min_distance <= max_distance, shrink in (0, 1], frame_stride and \
                 max_iterations >= 1; got {self:?}"
            )))
        }
    }
}

/// What the map alignment found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapAlignment {
    /// The aligned `reference_from_target`.
    pub reference_from_target: Isometry3<f64>,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the last step was below the tolerance at the final distance.
    pub converged: bool,
    /// Target samples with a map correspondence at the final distance.
    pub correspondences: usize,
    /// Target samples used.
    pub samples: usize,
    /// Share of the samples with a correspondence: how much of what the target saw the
    /// reference had seen too.
    pub fitness: f64,
    /// Root-mean-square point-to-plane residual of the correspondences (metres,
    /// Cauchy-weighted).
    pub rmse: f64,
    /// Points of the reference map.
    pub map_points: usize,
    /// `J^T W J` at the solution (tangent `[rho; phi]`, left perturbation of the extrinsic).
    pub information: Matrix6<f64>,
}

/// A target point and the frame it belongs to.
#[derive(Debug, Clone, Copy)]
struct Sample {
    point: Point3<f64>,
    frame: usize,
}

/// The reference map: the frames placed by `poses`, one point per voxel, the latest frame's.
fn reference_map(
    frames: &[Vec<Point3<f64>>],
    poses: &[Isometry3<f64>],
    voxel: f64,
) -> Result<SurfaceCloud> {
    let mut cells: FxHashMap<[i64; 3], Point3<f64>> = FxHashMap::default();
    for (frame, pose) in frames.iter().zip(poses) {
        for p in frame {
            let w = pose * p;
            cells.insert(cell_key(&w.coords, voxel), w);
        }
    }
    let mut entries: Vec<([i64; 3], Point3<f64>)> = cells.into_iter().collect();
    // Sorted by voxel, so the map (and every answer) does not depend on the hash's order.
    entries.sort_unstable_by_key(|(k, _)| *k);
    SurfaceCloud::new(entries.into_iter().map(|(_, p)| p).collect())
}

/// The target frames' samples: the first point of each voxel, frame by frame.
fn target_samples(frames: &[Vec<Point3<f64>>], voxel: f64, stride: usize) -> Vec<Sample> {
    let mut samples = Vec::new();
    for (frame, points) in frames.iter().enumerate().step_by(stride) {
        let mut seen = rustc_hash::FxHashSet::default();
        samples.extend(
            points
                .iter()
                .filter(|p| seen.insert(cell_key(&p.coords, voxel)))
                .map(|&point| Sample { point, frame }),
        );
    }
    samples
}

fn linearise(
    map: &SurfaceCloud,
    samples: &[Sample],
    poses: &[Isometry3<f64>],
    x: &Isometry3<f64>,
    distance: f64,
) -> PlaneSums {
    let loss = Loss::Cauchy {
        scale: distance / 3.0,
    };
    let mut sums: PlaneSums = accumulate(samples, |s, acc: &mut PlaneSums| {
        let Some(pose) = poses.get(s.frame) else {
            return;
        };
        let q = x * s.point;
        let w = pose * q;
        let Some((i, _)) = map.nearest(&w, distance) else {
            return;
        };
        let (Some(n), Some(m)) = (map.normal(i), map.points().get(i)) else {
            return;
        };
        // The Jacobian of a left perturbation of `X` is that of `q = X p` against the normal
        // seen from frame `k`.
        let nk = pose.rotation.inverse() * n;
        acc.add(n.dot(&(w - m)), &nk, &q.coords, loss);
    });
    sums.ne.symmetrize();
    sums
}

/// Aligns the target frames to the reference frames' map (see the module docs), from `initial`
/// (`reference_from_target`). `reference_poses[k]` places reference frame `k` (and, through the
/// extrinsic, target frame `k`) in the world.
///
/// Errors: [`Error::InvalidInput`] for bad options or mismatched lengths; [`Error::Calibration`]
/// of kind [`FailureKind::NoAgreement`] when fewer than 100 target samples find the reference
/// map at the start (the two sensors never saw the same places).
pub fn align_to_map(
    reference_frames: &[Vec<Point3<f64>>],
    reference_poses: &[Isometry3<f64>],
    target_frames: &[Vec<Point3<f64>>],
    initial: &Isometry3<f64>,
    options: &AlignOptions,
) -> Result<MapAlignment> {
    options.validate()?;
    if reference_frames.len() != reference_poses.len()
        || target_frames.len() != reference_poses.len()
    {
        return Err(Error::InvalidInput(format!(
            "map alignment needs one pose per frame: {} reference frames, {} poses, {} target \
             frames",
            reference_frames.len(),
            reference_poses.len(),
            target_frames.len()
        )));
    }
    let map = reference_map(reference_frames, reference_poses, options.map_voxel)?;
    let samples = target_samples(target_frames, options.sample_voxel, options.frame_stride);
    let mut x = *initial;
    let mut distance = options.max_distance;
    let mut iterations = 0;
    let mut converged = false;
    let mut sums = linearise(&map, &samples, reference_poses, &x, distance);
    while iterations < options.max_iterations {
        if sums.matched < MIN_CORRESPONDENCES {
            return Err(Error::calibration(
                FailureKind::NoAgreement,
                format!(
                    "only {} of the target's {} samples lie within {distance:.2} m of the \
                     reference's map: the two sensors did not see the same places during the \
                     drive (or the odometry lost them)",
                    sums.matched,
                    samples.len()
                ),
            ));
        }
        let h = sums.ne.hessian;
        let scale = (0..6).map(|i| h[(i, i)]).fold(0.0, f64::max).max(1e-12);
        let damped = h + Matrix6::identity() * (RIDGE * scale);
        let Some(step) = damped.cholesky().map(|c| c.solve(&(-sums.ne.gradient))) else {
            return Err(Error::Numerical(
                "map alignment: singular normal equations".into(),
            ));
        };
        x = se3_exp(&step) * x;
        x.rotation.renormalize();
        iterations += 1;
        let at_floor = distance <= options.min_distance;
        distance = (distance * options.shrink).max(options.min_distance);
        sums = linearise(&map, &samples, reference_poses, &x, distance);
        if at_floor && step.norm() < options.tolerance {
            converged = true;
            break;
        }
    }
    Ok(MapAlignment {
        reference_from_target: x,
        iterations,
        converged,
        correspondences: sums.matched,
        samples: samples.len(),
        fitness: sums.matched as f64 / samples.len().max(1) as f64,
        rmse: sums.rmse(),
        map_points: map.points().len(),
        information: sums.ne.hessian,
    })
}
