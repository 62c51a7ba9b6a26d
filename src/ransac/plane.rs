//! Plane estimation: the 3-point estimator, its scoring kernel, single-plane RANSAC and the
//! extraction of several planes with a joint refinement.
//!
//! # Why a joint refinement
//! Extracting planes one after another (as the planar-calibration seed does) hands the first plane
//! every point within the threshold, including the points of its neighbours near their
//! intersection lines. Those points pull the first planes' least-squares fits toward the
//! neighbours: a small but systematic tilt. [`extract_planes`] therefore reassigns every point to
//! its nearest plane, drops points within the threshold of two planes, and refits, for a few rounds.

use nalgebra::Point3;

use super::consensus::{ransac, search, search_points, Score, GROUP};
use super::kernel;
use super::{inliers_among, Cloud, Estimator, RansacOptions, RansacResult};
use crate::error::{Error, FailureKind, Result};
use crate::fit::Moments;
use crate::geometry::Plane;

/// A sample is degenerate when the sine of the angle between its two edges is below this.
const MIN_SAMPLE_SINE: f64 = 1e-6;

/// The 3-point plane estimator.
#[derive(Debug, Clone, Copy, Default)]
pub struct PlaneEstimator;

/// MSAC scores of up to [`GROUP`] planes (centred `f32` coefficients `[a, b, c, d]`) over the
/// structure-of-arrays cloud, in one pass (see [`super::kernel`]).
pub fn score_planes_f32(
    count_inliers: bool,
    x: &[f32],
    y: &[f32],
    z: &[f32],
    planes: &[[f32; 4]],
    threshold: f32,
    out: &mut [Score],
) {
    kernel::score(
        count_inliers,
        x,
        y,
        z,
        planes,
        threshold,
        out,
        |m, px, py, pz| {
            let dist = m[0] * px + m[1] * py + m[2] * pz + m[3];
            dist * dist
        },
    );
}

/// A plane's coefficients in the cloud's centred `f32` frame.
pub fn centred_coefficients(plane: &Plane, cloud: &Cloud<'_>) -> [f32; 4] {
    let n = plane.normal;
    let d = plane.offset + n.dot(&cloud.center());
    [n.x as f32, n.y as f32, n.z as f32, d as f32]
}

impl Estimator for PlaneEstimator {
    type Model = Plane;
    const SAMPLE_SIZE: usize = 3;
    const NAME: &'static str = "plane";

    fn minimal_model(&self, points: &[Point3<f64>], sample: &[usize]) -> Option<Plane> {
        let p0 = points.get(*sample.first()?)?;
        let e1 = points.get(*sample.get(1)?)? - p0;
        let e2 = points.get(*sample.get(2)?)? - p0;
        let normal = e1.cross(&e2);
        if normal.norm() <= MIN_SAMPLE_SINE * e1.norm() * e2.norm() {
            return None;
        }
        Plane::from_point_normal(p0, &normal).ok()
    }

    fn refit(&self, points: &[Point3<f64>], indices: &[usize]) -> Option<Plane> {
        let moments = Moments::from_points(indices.iter().filter_map(|&i| points.get(i)));
        moments.plane().ok().map(|fit| fit.plane)
    }

    fn squared_distance(&self, model: &Plane, p: &Point3<f64>) -> f64 {
        let d = model.signed_distance(p);
        d * d
    }

    fn score(
        &self,
        cloud: &Cloud<'_>,
        models: &[Plane],
        threshold: f64,
        count_inliers: bool,
        out: &mut [Score],
    ) {
        let (x, y, z) = cloud.soa();
        let coeffs: Vec<[f32; 4]> = models
            .iter()
            .map(|m| centred_coefficients(m, cloud))
            .collect();
        for (group, scores) in coeffs.chunks(GROUP).zip(out.chunks_mut(GROUP)) {
            score_planes_f32(count_inliers, x, y, z, group, threshold as f32, scores);
        }
    }

    fn check_cloud(&self, points: &[Point3<f64>]) -> Result<()> {
        Moments::from_points(points).plane().map(|_| ())
    }
}

/// The plane with the most support (MSAC) among `points`, refitted by least squares on its
/// inliers. The normal points toward the origin (the sensor).
pub fn ransac_plane(
    points: &[Point3<f64>],
    options: &RansacOptions,
) -> Result<RansacResult<Plane>> {
    let mut result = ransac(&PlaneEstimator, points, options)?;
    result.model = result.model.oriented_toward(&Point3::origin());
    Ok(result)
}

/// Options of [`extract_planes`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExtractOptions {
    /// Number of planes wanted.
    pub count: usize,
    /// A plane needs at least this many inliers to count.
    pub min_inliers: usize,
    /// Rounds of the joint reassignment and refit (0 keeps the sequential result).
    pub refinement_rounds: usize,
    /// Options of each RANSAC run (threshold, confidence, cap, seed).
    pub ransac: RansacOptions,
    /// When set (radians), a plane within this angle of an already accepted plane, or of the
    /// span of two accepted planes' normals, is discarded: its points leave the pool and the
    /// search goes on (at most 4 times). The calibration uses it to find three
    /// linearly independent planes when a surface comes in two parallel parts (a facade with a
    /// recessed storey, a curb beside a road) or a third wall is larger than the floor.
    pub min_angle_between: Option<f64>,
}

/// Most planes [`extract_planes`] discards as dependent on the accepted ones before giving up.
const MAX_DISCARDED: usize = 4;

impl ExtractOptions {
    /// `count` planes with threshold `distance_threshold`, at least 50 inliers each, 3 joint rounds.
    pub fn new(count: usize, distance_threshold: f64) -> Self {
        ExtractOptions {
            count,
            min_inliers: 50,
            refinement_rounds: 3,
            ransac: RansacOptions::new(distance_threshold),
            min_angle_between: None,
        }
    }
}

/// A plane found by [`extract_planes`].
#[derive(Debug, Clone, PartialEq)]
pub struct ExtractedPlane {
    /// The plane, normal toward the origin (the sensor).
    pub plane: Plane,
    /// Indices of its points (ascending): within the threshold of this plane and of no other.
    pub inliers: Vec<usize>,
    /// Root-mean-square distance of the inliers.
    pub rms: f64,
    /// Hypotheses drawn by the RANSAC run that found it.
    pub hypotheses: usize,
}

/// Assigns each point to the only plane within `threshold` of it; points near none or near two
/// or more planes (intersection lines) are left out.
fn assign(points: &[Point3<f64>], planes: &[Plane], threshold: f64) -> Vec<Vec<usize>> {
    // Each point's plane as a `u32` (`NONE` for none): 4 bytes a point rather than the 16 of an
    // `Option<usize>`, on a 1M-point scan 12 MB less at the corner method's peak memory.
    const NONE: u32 = u32::MAX;
    let owner = |p: &Point3<f64>| {
        let mut found = NONE;
        for (j, plane) in planes.iter().enumerate() {
            if plane.signed_distance(p).abs() < threshold {
                if found != NONE {
                    return NONE; // near two planes: an intersection line
                }
                // Fewer than 2^32 - 1 planes (each needs three points of its own).
                found = u32::try_from(j).unwrap_or(NONE);
            }
        }
        found
    };
    #[cfg(feature = "parallel")]
    let owners: Vec<u32> = if points.len() >= super::PARALLEL_MIN_POINTS {
        use rayon::prelude::*;
        points.par_iter().map(owner).collect()
    } else {
        points.iter().map(owner).collect()
    };
    #[cfg(not(feature = "parallel"))]
    let owners: Vec<u32> = points.iter().map(owner).collect();
    let mut groups = vec![Vec::new(); planes.len()];
    for (i, o) in owners.into_iter().enumerate() {
        if let Some(group) = groups.get_mut(o as usize) {
            group.push(i);
        }
    }
    groups
}

/// Whether `plane` adds no direction to the `accepted` ones: its normal lies within
/// `min_angle` of an accepted normal, or of the span of two of them (three walls and no floor:
/// three normals in one plane fix no corner).
fn dependent(accepted: &[(Plane, usize)], plane: &Plane, min_angle: f64) -> bool {
    let n = plane.normal.into_inner();
    let parallel = accepted
        .iter()
        .any(|(a, _)| a.normal.dot(&n).abs() > min_angle.cos());
    let in_span = accepted.iter().enumerate().any(|(i, (a, _))| {
        accepted.iter().skip(i + 1).any(|(b, _)| {
            let axis = a.normal.cross(&b.normal);
            let norm = axis.norm();
            norm > 0.0 && (axis.dot(&n) / norm).abs() < min_angle.sin()
        })
    });
    parallel || in_span
}

fn mix_seed(seed: u64, k: usize) -> u64 {
    // Distinct, well-spread seeds per extracted plane (SplitMix64 increment).
    seed.wrapping_add((k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

/// One run of the sequential RANSAC of [`extract_planes`]: a plane on the points not yet
/// `taken` (its inliers then marked taken), with the seed of run `run`. `None` when fewer than
/// `min_inliers` points remain, they are degenerate, or the best plane has fewer inliers. The
/// returned inliers index `points`.
///
/// It is [`ransac`](super::ransac) on the remaining points without a copy of them: the search
/// runs on the same stride of them (copied: at most [`MAX_SEARCH_POINTS`](super::consensus)
/// points), and the final support and refit read the remaining points in place, in the same
/// order. A copy of the remaining points (24 bytes each) had been most of the corner method's
/// peak memory on two 1M-point scans.
fn sequential_run<E: Estimator<Model = Plane>>(
    estimator: &E,
    points: &[Point3<f64>],
    taken: &mut [bool],
    options: &RansacOptions,
    run: usize,
    min_inliers: usize,
) -> Result<Option<RansacResult<Plane>>> {
    let remaining: Vec<usize> = (0..points.len()).filter(|&i| !taken[i]).collect();
    if remaining.len() < min_inliers {
        return Ok(None);
    }
    let ransac_options = RansacOptions {
        seed: mix_seed(options.seed, run),
        ..*options
    };
    let searched: Vec<Point3<f64>> = search_points(&remaining)
        .iter()
        .filter_map(|&i| points.get(i).copied())
        .collect();
    let found = match search(estimator, &searched, &ransac_options) {
        Ok(found) => found,
        Err(Error::Degenerate(_)) => return Ok(None),
        Err(e) => return Err(e),
    };
    // The final least-squares refit on the inliers of the best model, as `ransac` ends.
    let threshold = options.distance_threshold;
    let result = found.finish(estimator, points, |model| {
        inliers_among(estimator, points, &remaining, model, threshold)
    });
    if result.inliers.len() < min_inliers {
        return Ok(None);
    }
    for &i in &result.inliers {
        if let Some(t) = taken.get_mut(i) {
            *t = true;
        }
    }
    Ok(Some(result))
}

/// Extracts `options.count` planes: sequential RANSAC (each plane's inliers removed before the
/// next), then a joint refinement (see the module docs). Planes are returned largest first.
///
/// Errors: invalid options or points as for [`ransac_plane`]; [`Error::Calibration`] when fewer
/// than `count` planes with at least `min_inliers` inliers exist.
pub fn extract_planes(
    points: &[Point3<f64>],
    options: &ExtractOptions,
) -> Result<Vec<ExtractedPlane>> {
    options.ransac.validate()?;
    crate::error::ensure_points("points", points.iter())?;
    if options.count == 0 {
        return Err(Error::InvalidInput("count must be at least 1".into()));
    }
    let threshold = options.ransac.distance_threshold;
    let min_inliers = options.min_inliers.max(PlaneEstimator::SAMPLE_SIZE);
    let mut taken = vec![false; points.len()];
    let mut found: Vec<(Plane, usize)> = Vec::new();
    let mut discarded = 0;
    let mut run = 0;
    while found.len() < options.count {
        let Some(result) = sequential_run(
            &PlaneEstimator,
            points,
            &mut taken,
            &options.ransac,
            run,
            min_inliers,
        )?
        else {
            break;
        };
        run += 1;
        let too_parallel = options
            .min_angle_between
            .is_some_and(|min_angle| dependent(&found, &result.model, min_angle));
        if too_parallel {
            discarded += 1;
            if discarded > MAX_DISCARDED {
                break;
            }
            continue;
        }
        found.push((result.model, result.hypotheses));
    }
    if found.len() < options.count {
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!(
            "only {} plane(s) with at least {min_inliers} inliers within {threshold:.3} m were found, \
             {} wanted{}",
            found.len(),
            options.count,
            if discarded > 0 {
                format!(" ({discarded} more discarded as parallel to those or to their span)")
            } else {
                String::new()
            }
        ),
        ));
    }

    let mut extracted = joint_refit(
        points,
        &found,
        threshold,
        min_inliers,
        options.refinement_rounds,
    )?;
    extracted.sort_by_key(|p| std::cmp::Reverse(p.inliers.len()));
    Ok(extracted)
}

/// The joint refinement of [`extract_planes`]: `rounds` times each point goes to the only plane
/// within `threshold` of it and the planes are refitted; then the final assignment. The planes
/// keep their order.
///
/// Errors: [`Error::Calibration`] when a plane keeps fewer than `min_inliers` inliers.
pub(crate) fn joint_refit(
    points: &[Point3<f64>],
    found: &[(Plane, usize)],
    threshold: f64,
    min_inliers: usize,
    rounds: usize,
) -> Result<Vec<ExtractedPlane>> {
    let mut planes: Vec<Plane> = found.iter().map(|(p, _)| *p).collect();
    for _ in 0..rounds {
        let groups = assign(points, &planes, threshold);
        let mut changed = false;
        for (plane, group) in planes.iter_mut().zip(&groups) {
            if let Some(refit) = PlaneEstimator.refit(points, group) {
                changed |= refit != *plane;
                *plane = refit;
            }
        }
        if !changed {
            break;
        }
    }
    let groups = assign(points, &planes, threshold);
    let extracted: Vec<ExtractedPlane> = planes
        .iter()
        .zip(groups)
        .zip(found)
        .map(|((plane, inliers), (_, hypotheses))| ExtractedPlane {
            plane: plane.oriented_toward(&Point3::origin()),
            rms: super::rms(&PlaneEstimator, points, plane, &inliers),
            inliers,
            hypotheses: *hypotheses,
        })
        .collect();
    if let Some(weak) = extracted.iter().find(|p| p.inliers.len() < min_inliers) {
        return Err(Error::calibration(
            FailureKind::TooFewFeatures,
            format!(
                "after the joint refinement a plane keeps only {} inliers (< {min_inliers})",
                weak.inliers.len()
            ),
        ));
    }
    Ok(extracted)
}

/// [`PlaneEstimator`] that turns down every minimal sample whose plane lies more than
/// `acos(min_cos)` from all of `normals` (either way): [`parallel_alternates`] wants only planes
/// beside accepted ones, and scoring a hypothesis against the cloud is most of a RANSAC run, so
/// on the noise and clutter left by a corner's three planes this skips about 19 in 20 of them
/// (a random normal lies within 10 degrees of one of three axes, either way, 4.6 % of the time).
struct ParallelPlanes {
    normals: Vec<nalgebra::Vector3<f64>>,
    min_cos: f64,
}

impl Estimator for ParallelPlanes {
    type Model = Plane;
    const SAMPLE_SIZE: usize = PlaneEstimator::SAMPLE_SIZE;
    const NAME: &'static str = PlaneEstimator::NAME;

    fn minimal_model(&self, points: &[Point3<f64>], sample: &[usize]) -> Option<Plane> {
        let plane = PlaneEstimator.minimal_model(points, sample)?;
        self.normals
            .iter()
            .any(|n| n.dot(&plane.normal).abs() > self.min_cos)
            .then_some(plane)
    }

    fn refit(&self, points: &[Point3<f64>], indices: &[usize]) -> Option<Plane> {
        PlaneEstimator.refit(points, indices)
    }

    fn squared_distance(&self, model: &Plane, p: &Point3<f64>) -> f64 {
        PlaneEstimator.squared_distance(model, p)
    }

    fn score(
        &self,
        cloud: &Cloud<'_>,
        models: &[Plane],
        threshold: f64,
        count_inliers: bool,
        out: &mut [Score],
    ) {
        PlaneEstimator.score(cloud, models, threshold, count_inliers, out)
    }

    fn check_cloud(&self, points: &[Point3<f64>]) -> Result<()> {
        PlaneEstimator.check_cloud(points)
    }
}

/// A plane parallel to one of a cloud's accepted planes: a candidate for its role.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Alternate {
    /// Index of the accepted plane it is parallel to.
    pub(crate) role: usize,
    /// The plane, normal toward the origin (the sensor).
    pub(crate) plane: Plane,
    /// Hypotheses drawn by the RANSAC run that found it.
    pub(crate) hypotheses: usize,
    /// Its inliers among the points the accepted planes leave.
    pub(crate) inliers: usize,
    /// Its normal (toward the sensor) opposes the accepted plane's: the far wall of a room.
    pub(crate) opposed: bool,
}

/// The planes parallel to the `accepted` ones, the next candidates for their roles: sequential
/// RANSAC as in [`extract_planes`] on the points farther than the threshold from every accepted
/// plane, at most `runs` planes of at least `options.min_inliers` inliers. Those whose normal
/// lies within `max_angle` of an accepted plane's, either way, are returned with its index, largest
/// first: a box top or a pavement beside the ground, a street's other facade, a room's far wall.
/// Only hypotheses within `max_angle` of an accepted plane are scored ([`ParallelPlanes`]); a
/// run's least-squares refit can still leave that angle, and such a plane is skipped (its points
/// stay taken).
pub(crate) fn parallel_alternates(
    points: &[Point3<f64>],
    accepted: &[Plane],
    options: &ExtractOptions,
    runs: usize,
    max_angle: f64,
) -> Result<Vec<Alternate>> {
    let threshold = options.ransac.distance_threshold;
    let min_inliers = options.min_inliers.max(PlaneEstimator::SAMPLE_SIZE);
    let mut taken: Vec<bool> = points
        .iter()
        .map(|q| {
            accepted
                .iter()
                .any(|p| p.signed_distance(q).abs() < threshold)
        })
        .collect();
    let parallel = ParallelPlanes {
        normals: accepted.iter().map(|p| p.normal.into_inner()).collect(),
        min_cos: max_angle.cos(),
    };
    let mut alternates = Vec::new();
    for run in 0..runs {
        // Seeds after those extract_planes can have used for the accepted planes.
        let seed_run = accepted.len() + MAX_DISCARDED + 1 + run;
        let Some(result) = sequential_run(
            &parallel,
            points,
            &mut taken,
            &options.ransac,
            seed_run,
            min_inliers,
        )?
        else {
            break;
        };
        let plane = result.model.oriented_toward(&Point3::origin());
        let role = accepted
            .iter()
            .position(|a| a.normal.dot(&plane.normal).abs() > max_angle.cos());
        if let Some(role) = role {
            alternates.push(Alternate {
                role,
                plane,
                hypotheses: result.hypotheses,
                inliers: result.inliers.len(),
                opposed: accepted[role].normal.dot(&plane.normal) < 0.0,
            });
        }
    }
    alternates.sort_by_key(|a| std::cmp::Reverse(a.inliers));
    Ok(alternates)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// A grid of points on the plane through `origin` spanned by `u` and `v`, `n` by `n`, `step`
    /// apart.
    fn patch(origin: [f64; 3], u: [f64; 3], v: [f64; 3], n: usize, step: f64) -> Vec<Point3<f64>> {
        let (o, u, v) = (Vector3::from(origin), Vector3::from(u), Vector3::from(v));
        (0..n * n)
            .map(|k| {
                let (i, j) = ((k / n) as f64, (k % n) as f64);
                Point3::from(o + u * (i * step) + v * (j * step))
            })
            .collect()
    }

    /// The options of the next-plane tests (three planes 20 degrees apart at least, 2 cm) and the
    /// three planes `extract_planes` takes from `points` under them.
    fn three_planes(points: &[Point3<f64>]) -> (ExtractOptions, Vec<Plane>) {
        let mut options = ExtractOptions::new(3, 0.02);
        options.min_angle_between = Some(20f64.to_radians());
        let accepted = extract_planes(points, &options)
            .unwrap()
            .iter()
            .map(|p| p.plane)
            .collect();
        (options, accepted)
    }

    #[test]
    fn parallel_alternates_score_only_parallel_hypotheses() {
        // A floor, two walls, a ramp at 30 degrees larger than anything left, and a box top
        // 1 m above the floor. With one run, unconstrained RANSAC would take the ramp (and skip
        // it); only hypotheses beside an accepted plane are scored, so the run finds the box top.
        let mut points = patch([0.0, 0.0, -1.5], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 50, 0.1);
        points.extend(patch(
            [0.0, 5.0, -1.5],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            50,
            0.06,
        ));
        points.extend(patch(
            [5.0, 0.0, -1.5],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            50,
            0.06,
        ));
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        points.extend(patch(
            [-6.0, -3.0, -1.5],
            [0.0, 1.0, 0.0],
            [-c, 0.0, s],
            40,
            0.06,
        ));
        points.extend(patch(
            [1.0, 1.0, -0.5],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            12,
            0.1,
        ));
        let (options, accepted) = three_planes(&points);
        assert!(accepted
            .iter()
            .all(|p| p.normal.dot(&Vector3::z()).abs() > 0.99
                || p.normal.dot(&Vector3::z()).abs() < 0.01));
        let found =
            parallel_alternates(&points, &accepted, &options, 1, 10f64.to_radians()).unwrap();
        assert_eq!(found.len(), 1, "{found:?}");
        assert!((found[0].plane.offset - 0.5).abs() < 0.02, "{found:?}");
        // The box top's 144 points and the ramp's row that crosses its height.
        assert_eq!(found[0].inliers, 184);
    }

    #[test]
    fn parallel_alternates_finds_a_box_top_and_a_far_wall() {
        // The ground 1.5 m below the sensor, a box top 1 m above it, a wall 4 m to the side and
        // its opposite wall 3 m to the other side, a wall ahead.
        let mut points = patch(
            [-5.0, -2.9, -1.5],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            60,
            0.1,
        );
        points.extend(patch(
            [1.0, 1.0, -0.5],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            12,
            0.1,
        ));
        points.extend(patch(
            [-5.0, 4.0, -1.5],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            60,
            0.05,
        ));
        points.extend(patch(
            [-5.0, -3.0, -1.5],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            40,
            0.05,
        ));
        points.extend(patch(
            [6.0, -2.9, -1.4],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            50,
            0.05,
        ));
        let (options, accepted) = three_planes(&points);
        let role_of = |normal: Vector3<f64>| {
            accepted
                .iter()
                .position(|p| p.normal.dot(&normal).abs() > 0.99)
                .unwrap()
        };
        let (ground, side) = (role_of(Vector3::z()), role_of(Vector3::y()));
        let found =
            parallel_alternates(&points, &accepted, &options, 4, 10f64.to_radians()).unwrap();
        let box_top = found
            .iter()
            .find(|a| (a.plane.offset - 0.5).abs() < 0.02)
            .expect("the box top");
        assert_eq!((box_top.role, box_top.opposed), (ground, false));
        assert_eq!(box_top.inliers, 144);
        let far_wall = found
            .iter()
            .find(|a| a.role == side && a.opposed)
            .expect("the opposite wall");
        assert!(
            (far_wall.plane.offset - 3.0).abs() < 0.02
                || (far_wall.plane.offset - 4.0).abs() < 0.02
        );
        // Every alternate is parallel to its role's plane, and none is an accepted plane again.
        for a in &found {
            let dot = accepted[a.role].normal.dot(&a.plane.normal);
            assert!(dot.abs() > 10f64.to_radians().cos());
            assert_eq!(a.opposed, dot < 0.0);
            assert!(accepted
                .iter()
                .all(|p| (p.coefficients() - a.plane.coefficients()).norm() > 0.05));
        }
    }
}
