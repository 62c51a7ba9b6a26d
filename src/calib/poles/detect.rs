//! Steps 1-3 of the [module docs](super): the bright returns, their clusters and the pole test
//! (splitting clusters of crossing poles).

use nalgebra::Point3;

use super::fit::*;
use super::ground::*;
use super::hypotheses::*;
use super::options::*;
use super::threshold::*;
use crate::budget::Deadline;
use crate::calib::input::with_cloud;
use crate::cluster::euclidean_clusters_until;
use crate::error::{Error, FailureKind, Result};
use crate::fit::Moments;
use crate::geometry::{Line, Plane};
use crate::ransac::line::ransac_line;
use crate::ransac::RansacOptions;

/// Line inlier distance when splitting a merged cluster with an unknown radius (metres).
const SPLIT_LINE_THRESHOLD: f64 = 0.2;
/// Shortest cluster that is split into several lines (metres): crossing poles, not a sign.
pub(super) const SPLIT_MIN_LENGTH: f64 = 1.0;
/// Smallest elongation of each piece of a split cluster.
const SPLIT_MIN_ELONGATION: f64 = 3.0;

/// A pole found in one cloud.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectedPole {
    /// The axis (cylinder axis or line), in the cloud's frame; the point is the foot of the
    /// points' centroid.
    pub axis: Line,
    /// Fitted or given radius (0 for [`AxisFit::Line`]).
    pub radius: f64,
    /// RMS residual of the axis fit (metres).
    pub rms: f64,
    /// Indices of the pole's points (RANSAC inliers) in the cloud.
    pub indices: Vec<usize>,
    /// Extent of the points along the axis, `(min, max)` from the axis point (metres).
    pub extent: (f64, f64),
}

/// A bright cluster that was not taken as a pole.
#[derive(Debug, Clone, PartialEq)]
pub struct RejectedCluster {
    /// Points in the cluster.
    pub size: usize,
    /// Why it was rejected.
    pub reason: String,
}

/// The poles of one cloud.
#[derive(Debug, Clone, PartialEq)]
pub struct PoleExtraction {
    /// The intensity threshold used.
    pub intensity_threshold: f64,
    /// Returns at or above it.
    pub bright_points: usize,
    /// The poles, largest first.
    pub poles: Vec<DetectedPole>,
    /// Clusters of at least `min_points` that failed a pole test.
    pub rejected: Vec<RejectedCluster>,
}

/// Finds the poles of one cloud (steps 1–4 of the module docs).
pub fn extract_poles(
    points: &[Point3<f64>],
    intensities: &[f64],
    options: &PoleOptions,
) -> Result<PoleExtraction> {
    extract_poles_until(
        points,
        intensities,
        options,
        &Deadline::new(options.time_budget),
    )
}

/// [`extract_poles`] against a deadline set by the caller.
pub(super) fn extract_poles_until(
    points: &[Point3<f64>],
    intensities: &[f64],
    options: &PoleOptions,
    deadline: &Deadline,
) -> Result<PoleExtraction> {
    check_cloud(points, intensities, "input")?;
    check_options(options)?;
    let threshold = match (options.intensity_threshold, options.vendor) {
        (Some(t), _) => t,
        (None, Some(v)) => v.threshold(),
        (None, None) => data_threshold(intensities)?,
    };
    let bright: Vec<usize> = (0..points.len())
        .filter(|&i| intensities[i] >= threshold)
        .collect();
    if bright.len() < options.min_points {
        let max = intensities
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!(
            "only {} bright point(s) at or above intensity {threshold:.1} (need {} per pole; the \
             highest intensity is {max:.1}): no taped poles visible, or the threshold is too high",
            bright.len(),
            options.min_points
        ),
        ));
    }
    let share = bright.len() as f64 / points.len() as f64;
    if share > options.max_bright_fraction {
        let suggestion = match data_threshold(intensities) {
            Ok(t) => format!("this cloud's data-driven threshold is {t:.1}"),
            Err(_) => "this cloud has no clear bright class either".into(),
        };
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!(
            "intensity threshold {threshold:.1} marks {:.1} % of the returns as tape (more than \
             {:.0} %): tape is a small part of a scene, so this threshold does not separate it; \
             raise it ({suggestion}), or, for a cloud cropped to the poles, raise \
             max_bright_fraction",
            100.0 * share,
            100.0 * options.max_bright_fraction
        ),
        ));
    }
    let bright_points: Vec<Point3<f64>> = bright.iter().map(|&i| points[i]).collect();
    let clusters = euclidean_clusters_until(&bright_points, options.cluster_tolerance, deadline)?;
    let mut poles = Vec::new();
    let mut rejected = Vec::new();
    for cluster in clusters {
        if cluster.len() < options.min_points {
            continue;
        }
        let members: Vec<Point3<f64>> = cluster.iter().map(|&k| bright_points[k]).collect();
        let indices: Vec<usize> = cluster.iter().map(|&k| bright[k]).collect();
        match fit_pole(&members, &indices, options) {
            Ok(pole) => poles.push(pole),
            Err(reason) => {
                // Poles that lean on each other (an X) form one compact-looking cluster: look for
                // several lines in it before giving up.
                let split = split_cluster(&members, &indices, options);
                if split.is_empty() {
                    rejected.push(RejectedCluster {
                        size: cluster.len(),
                        reason,
                    });
                } else {
                    poles.extend(split);
                }
            }
        }
    }
    poles.sort_by_key(|p| std::cmp::Reverse(p.indices.len()));
    poles.truncate(options.max_poles);
    Ok(PoleExtraction {
        intensity_threshold: threshold,
        bright_points: bright.len(),
        poles,
        rejected,
    })
}

/// Steps 1-4 on one cloud of [`calibrate_poles`](super::calibrate_poles): its poles (at least a
/// non-parallel pair, else the calibration is refused) and its largest plane among the returns
/// below the intensity threshold. `which` names the cloud in errors.
pub(super) fn detect_cloud(
    points: &[Point3<f64>],
    intensities: &[f64],
    which: &str,
    options: &PoleOptions,
    deadline: &Deadline,
) -> Result<(PoleExtraction, Option<Plane>)> {
    let extraction = extract_poles_until(points, intensities, options, deadline)
        .map_err(|e| with_cloud(e, which))?;
    // The tape is left out: the front faces of two poles can pass for a plane.
    let dull: Vec<Point3<f64>> = points
        .iter()
        .zip(intensities)
        .filter(|(_, &i)| i < extraction.intensity_threshold)
        .map(|(p, _)| *p)
        .collect();
    let plane = largest_plane(&dull, points.len(), options.seed);
    check_poles(&extraction, which).map(|_| (extraction, plane))
}

/// Sequential RANSAC lines in a cluster that failed the pole test as a whole (poles crossing or
/// touching); every line's inliers must pass the pole test on their own with an elongation of at
/// least [`SPLIT_MIN_ELONGATION`]. Only clusters of at least two poles' worth of points and
/// [`SPLIT_MIN_LENGTH`] are split, so a compact sign stays whole and is rejected.
pub(super) fn split_cluster(
    members: &[Point3<f64>],
    indices: &[usize],
    options: &PoleOptions,
) -> Vec<DetectedPole> {
    let mut out = Vec::new();
    if members.len() < 2 * options.min_points {
        return out;
    }
    // Only a cluster at least as long as a pole can hold crossing poles; a sign is not split.
    let moments = Moments::from_points(members);
    let (_, vectors) = moments.principal_axes();
    let (lo, hi) = extent_along(members, &moments.mean(), &vectors[2]);
    if hi - lo < SPLIT_MIN_LENGTH {
        return out;
    }
    // Each piece must be clearly a line on its own.
    let strict = PoleOptions {
        min_elongation: options.min_elongation.max(SPLIT_MIN_ELONGATION),
        min_length: options.min_length.max(0.5 * SPLIT_MIN_LENGTH),
        ..*options
    };
    let options = &strict;
    let threshold = options
        .pole_radius
        .map_or(SPLIT_LINE_THRESHOLD, |r| 1.2 * r + 0.03);
    let mut remaining: Vec<usize> = (0..members.len()).collect();
    for round in 0..options.max_poles {
        if remaining.len() < options.min_points {
            break;
        }
        let pts: Vec<Point3<f64>> = remaining.iter().map(|&k| members[k]).collect();
        let mut ransac = RansacOptions::new(threshold);
        ransac.seed = options.seed.wrapping_add(round as u64);
        let Ok(line) = ransac_line(&pts, &ransac) else {
            break;
        };
        if line.inliers.len() < options.min_points {
            break;
        }
        let sub: Vec<Point3<f64>> = line.inliers.iter().map(|&k| pts[k]).collect();
        let sub_indices: Vec<usize> = line
            .inliers
            .iter()
            .map(|&k| indices[remaining[k]])
            .collect();
        if let Ok(pole) = fit_pole(&sub, &sub_indices, options) {
            out.push(pole);
        }
        let taken: std::collections::HashSet<usize> = line.inliers.iter().copied().collect();
        remaining = remaining
            .iter()
            .enumerate()
            .filter(|(k, _)| !taken.contains(k))
            .map(|(_, &m)| m)
            .collect();
    }
    out
}

pub(super) fn check_poles(extraction: &PoleExtraction, which: &str) -> Result<()> {
    let n = extraction.poles.len();
    let rejected = || {
        if extraction.rejected.is_empty() {
            String::new()
        } else {
            let parts: Vec<String> = extraction
                .rejected
                .iter()
                .map(|r| format!("{} points: {}", r.size, r.reason))
                .collect();
            format!("; rejected clusters: {}", parts.join("; "))
        }
    };
    if n < 2 {
        return Err(Error::calibration(FailureKind::TooFewFeatures, format!(
            "{which} cloud: found {n} pole(s) among {} bright points (intensity >= {:.1}); need two \
             non-parallel taped poles{}",
            extraction.bright_points,
            extraction.intensity_threshold,
            rejected()
        )));
    }
    if base_pair(&extraction.poles).is_none() {
        let widest = (0..n)
            .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
            .map(|(i, j)| angle_between_lines(&extraction.poles[i].axis, &extraction.poles[j].axis))
            .fold(0.0, f64::max);
        return Err(Error::calibration(
            FailureKind::Unobservable,
            format!(
            "{which} cloud: the {n} poles are parallel within {:.1} deg (widest angle {:.2} deg): \
             they do not determine the rotation about them",
            MIN_POLE_ANGLE.to_degrees(),
            widest.to_degrees()
        ),
        ));
    }
    Ok(())
}
