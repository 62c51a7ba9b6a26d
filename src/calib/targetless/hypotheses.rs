//! Step 3: pose hypotheses from matched plane pairs and triplets, the ground sweep, and the slides
//! of pair hypotheses along the direction their planes leave free.

use std::collections::{HashMap, HashSet};

use nalgebra::{Isometry3, Matrix3, Point3, Translation3, Vector3};

use super::options::TargetlessOptions;
use super::segment::PlaneFeature;
use super::verify::VIOLATION_WEIGHT;
use crate::calib::input::isometry;
use crate::geometry::cell_key;
use crate::kabsch::kabsch;
use crate::visibility::RangeImage;

/// Two planes of a hypothesis pair must be at least this far from parallel (radians, 30 degrees).
pub(super) const MIN_PAIR_ANGLE: f64 = 30.0 * std::f64::consts::PI / 180.0;
/// A third plane completes a triplet when its normal leaves the pair's span by at least this
/// angle (radians, 20 degrees).
const MIN_THIRD_ANGLE: f64 = 20.0 * std::f64::consts::PI / 180.0;
/// Most hypotheses enumerated (pairs and triplets, before deduplication).
const MAX_HYPOTHESES: usize = 50_000;
/// Hypotheses within this rotation (radians, 1 degree) ...
const DUPLICATE_ANGLE: f64 = 1.0 * std::f64::consts::PI / 180.0;
/// ... and translation (metres) of each other are one.
const DUPLICATE_DISTANCE: f64 = 0.1;
/// Yaw step of the ground sweep (radians, 15 degrees): the hypotheses that level the largest
/// plane of each cloud onto the other's and turn about its normal.
pub(super) const SWEEP_STEP: f64 = 15.0 * std::f64::consts::PI / 180.0;
/// Largest planes of the target tried as the reference's largest plane in the ground sweep.
const SWEEP_TARGET_PLANES: usize = 1;
/// Step (metres) of the slide of a plane-pair hypothesis along the direction its planes leave
/// free (the axis of a street): see the module docs, step 3.
pub(super) const SLIDE_STEP: f64 = 0.5;
/// Farthest a hypothesis slides (metres) when [`TargetlessOptions::max_translation`] is larger
/// (or infinite).
const SLIDE_RANGE: f64 = 10.0;
/// A slid target point agrees when it lands in a cell of this side (metres) that holds a reference
/// point: as coarse as the step, so the best offset is found before any ICP.
pub(super) const SLIDE_CELL: f64 = 0.5;
/// Target points (at most, by a fixed stride) scored at every slide offset.
pub(super) const SLIDE_SAMPLES: usize = 400;
/// Offsets closer than this to the hypothesis' own (metres) are left to its screening ICP.
const SLIDE_MIN: f64 = 0.75;
/// Local maxima of the slide score of the best pose probed for a repeated structure (see
/// [`calibrate_targetless`](super::calibrate_targetless)): the best ones, where a slid copy the
/// check cannot tell from the best pose makes the result ambiguous.
pub(super) const SLIDE_PEAKS: usize = 2;
/// Local maxima probed for a slid copy that keeps the free space clearly clearer than the best
/// pose: the truth of adversarial poles 11189, 1.09 m along the free direction of a best pose
/// that put 3.4 % of the points into free space (0.8 % there), was the third peak. (Counting
/// indistinguishable copies at the third and fourth peaks as well refused two identical boxes,
/// repeated 63, over a slide 1 m along them.)
pub(super) const CLEARER_SLIDE_PEAKS: usize = 4;

/// A candidate transform from plane correspondences.
#[derive(Debug, Clone, Copy)]
pub(super) struct Candidate {
    pub(super) pose: Isometry3<f64>,
    /// Unit direction of translation no plane of the hypothesis fixes (pairs only).
    pub(super) free: Option<Vector3<f64>>,
    pub(super) support: f64,
    /// From the ground sweep rather than a plane pair.
    pub(super) sweep: bool,
}

pub(super) fn angle_between(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.dot(b).clamp(-1.0, 1.0).acos()
}

/// Least squares `t` from rows `n_i . t = b_i`: the minimum-norm solution when the normals span
/// two directions, with the free direction.
pub(super) fn solve_translation(
    normals: &[Vector3<f64>],
    rhs: &[f64],
) -> Option<(Vector3<f64>, Option<Vector3<f64>>)> {
    let mut ata = Matrix3::zeros();
    let mut atb = Vector3::zeros();
    for (n, b) in normals.iter().zip(rhs) {
        ata += n * n.transpose();
        atb += n * *b;
    }
    let eig = nalgebra::SymmetricEigen::new(ata);
    let largest = eig.eigenvalues.amax();
    if largest <= 0.0 {
        return None;
    }
    let mut t = Vector3::zeros();
    let mut free = None;
    for k in 0..3 {
        let v = eig.eigenvectors.column(k).into_owned();
        let l = eig.eigenvalues[k];
        if l > 0.04 * largest {
            t += v * (v.dot(&atb) / l);
        } else if free.is_none() {
            free = Some(v);
        } else {
            return None; // one direction only
        }
    }
    Some((t, free))
}

/// Keeps the first of each group of candidates within [`DUPLICATE_ANGLE`] and
/// [`DUPLICATE_DISTANCE`] of a kept one, in order. Kept poses are hashed by translation in cells of
/// [`DUPLICATE_DISTANCE`], so a candidate is compared only with those of the 27 neighbouring cells:
/// the same result as comparing with every kept one, without the quadratic cost (a scan of a
/// building with many planes gives ~10 000 scored hypotheses and ~7 000 distinct ones).
pub(super) fn deduplicate(candidates: Vec<Candidate>) -> Vec<Candidate> {
    let cell = |v: &Vector3<f64>| cell_key(v, DUPLICATE_DISTANCE);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    let mut distinct: Vec<Candidate> = Vec::with_capacity(candidates.len());
    for c in candidates {
        let key = cell(&c.pose.translation.vector);
        let mut duplicate = false;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let near = [key[0] + dx, key[1] + dy, key[2] + dz];
                    let Some(kept) = grid.get(&near) else {
                        continue;
                    };
                    if kept.iter().any(|&i| {
                        distinct.get(i).is_some_and(|d| {
                            same_pose(&d.pose, &c.pose, DUPLICATE_ANGLE, DUPLICATE_DISTANCE)
                        })
                    }) {
                        duplicate = true;
                        break 'search;
                    }
                }
            }
        }
        if !duplicate {
            grid.entry(key).or_default().push(distinct.len());
            distinct.push(c);
        }
    }
    distinct
}

pub(super) fn same_pose(a: &Isometry3<f64>, b: &Isometry3<f64>, angle: f64, distance: f64) -> bool {
    let d = a.inverse() * b;
    d.rotation.angle() < angle && (a.translation.vector - b.translation.vector).norm() < distance
}

/// Matches every target plane to the best agreeing reference plane under `pose`:
/// `(reference index, target index)` pairs. Offsets are checked except along `free`.
pub(super) fn agreeing(
    reference: &[PlaneFeature],
    target: &[PlaneFeature],
    pose: &Isometry3<f64>,
    free: Option<&Vector3<f64>>,
    normal_tolerance: f64,
    offset_tolerance: f64,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for (j, t) in target.iter().enumerate() {
        let mapped = t.plane.transformed(pose);
        let n = mapped.normal.into_inner();
        let offset_known = free.is_none_or(|v| n.dot(v).abs() < 0.2);
        let mut best: Option<(usize, f64)> = None;
        for (i, r) in reference.iter().enumerate() {
            let angle = angle_between(&n, &r.plane.normal);
            if angle > normal_tolerance {
                continue;
            }
            let gap = (mapped.offset - r.plane.offset).abs();
            if offset_known && gap > offset_tolerance {
                continue;
            }
            let cost = angle / normal_tolerance + if offset_known { gap } else { 1.0 };
            if best.is_none_or(|(_, c)| cost < c) {
                best = Some((i, cost));
            }
        }
        if let Some((i, _)) = best {
            out.push((i, j));
        }
    }
    out
}

pub(super) fn support(
    reference: &[PlaneFeature],
    target: &[PlaneFeature],
    matches: &[(usize, usize)],
) -> f64 {
    matches
        .iter()
        .filter_map(|&(i, j)| Some((reference.get(i)?.voxels.len(), target.get(j)?.voxels.len())))
        .map(|(a, b)| (a.min(b) as f64).sqrt())
        .sum()
}

/// Every pair and triplet hypothesis (step 3 of the module docs); `(enumerated, distinct)`.
pub(super) fn hypotheses(
    reference: &[PlaneFeature],
    target: &[PlaneFeature],
    options: &TargetlessOptions,
) -> (usize, Vec<Candidate>) {
    let tol = options.normal_tolerance;
    let n_ref: Vec<Vector3<f64>> = reference
        .iter()
        .map(|f| f.plane.normal.into_inner())
        .collect();
    let n_tgt: Vec<Vector3<f64>> = target.iter().map(|f| f.plane.normal.into_inner()).collect();
    let mut raw: Vec<Candidate> = Vec::new();
    let mut enumerated = 0usize;
    'outer: for i in 0..n_ref.len() {
        for j in (i + 1)..n_ref.len() {
            let angle_ref = angle_between(&n_ref[i], &n_ref[j]);
            if !(MIN_PAIR_ANGLE..=std::f64::consts::PI - MIN_PAIR_ANGLE).contains(&angle_ref) {
                continue;
            }
            for k in 0..n_tgt.len() {
                for l in 0..n_tgt.len() {
                    if k == l || (angle_between(&n_tgt[k], &n_tgt[l]) - angle_ref).abs() > tol {
                        continue;
                    }
                    let a = [n_ref[i], n_ref[j], n_ref[i].cross(&n_ref[j]).normalize()];
                    let b = [n_tgt[k], n_tgt[l], n_tgt[k].cross(&n_tgt[l]).normalize()];
                    let Ok(solution) = kabsch(&a, &b, None) else {
                        continue;
                    };
                    let r = solution.rotation;
                    let d = |f: &PlaneFeature| f.plane.offset;
                    let mut rows = vec![n_ref[i], n_ref[j]];
                    let mut rhs = vec![
                        d(&target[k]) - d(&reference[i]),
                        d(&target[l]) - d(&reference[j]),
                    ];
                    let span = a[2];
                    for m in 0..n_tgt.len() {
                        if m == k || m == l {
                            continue;
                        }
                        let mapped = r * n_tgt[m];
                        if mapped.dot(&span).abs() < MIN_THIRD_ANGLE.sin() {
                            continue;
                        }
                        for (p, np) in n_ref.iter().enumerate() {
                            if angle_between(&mapped, np) > tol {
                                continue;
                            }
                            rows.push(*np);
                            rhs.push(d(&target[m]) - d(&reference[p]));
                            if let Some((t, None)) = solve_translation(&rows, &rhs) {
                                raw.push(Candidate {
                                    pose: isometry(&r, t),
                                    free: None,
                                    support: 0.0,
                                    sweep: false,
                                });
                            }
                            rows.pop();
                            rhs.pop();
                            enumerated += 1;
                        }
                    }
                    // The pair alone too, even when thirds were found: a third plane matched
                    // by its normal only may be another facade of the same direction (a street
                    // grid), and then only the pair, slid along its free direction, reaches the
                    // truth.
                    if let Some((t, free)) = solve_translation(&rows, &rhs) {
                        raw.push(Candidate {
                            pose: isometry(&r, t),
                            free,
                            support: 0.0,
                            sweep: false,
                        });
                    }
                    enumerated += 1;
                    if enumerated >= MAX_HYPOTHESES {
                        break 'outer;
                    }
                }
            }
        }
    }
    // Score, then deduplicate keeping the best supported of each cluster.
    let reach = options.max_translation * options.challenger_range;
    raw.retain(|c| c.pose.translation.vector.norm() <= reach);
    for c in &mut raw {
        let matches = agreeing(
            reference,
            target,
            &c.pose,
            c.free.as_ref(),
            tol,
            options.offset_tolerance,
        );
        c.support = support(reference, target, &matches);
    }
    raw.sort_by(|a, b| {
        b.support
            .total_cmp(&a.support)
            .then_with(|| a.free.is_some().cmp(&b.free.is_some()))
    });
    (enumerated, deduplicate(raw))
}

/// The ground-sweep hypotheses (see [`TargetlessOptions::ground_sweep`]): the largest reference
/// plane matched to each of the [`SWEEP_TARGET_PLANES`] largest target planes (normals aligned,
/// offsets equal), turned about its normal in [`SWEEP_STEP`] steps; the in-plane translation is
/// zero (the sensors of one rig are close together) and left to ICP.
pub(super) fn ground_sweep(reference: &[PlaneFeature], target: &[PlaneFeature]) -> Vec<Candidate> {
    let mut out = Vec::new();
    let Some(ground) = reference.first() else {
        return out;
    };
    let n_ref = ground.plane.normal;
    let steps = (std::f64::consts::TAU / SWEEP_STEP).round() as usize;
    for t in target.iter().take(SWEEP_TARGET_PLANES) {
        let n_tgt = t.plane.normal;
        // Normals face their sensors, so the target plane's normal maps onto the reference's.
        let align = nalgebra::Rotation3::rotation_between(&n_tgt.into_inner(), &n_ref.into_inner())
            .unwrap_or_else(|| {
                // Opposite normals: half a turn about any perpendicular axis.
                let axis = n_ref.cross(&Vector3::x());
                let axis = if axis.norm() > 0.1 {
                    axis
                } else {
                    n_ref.cross(&Vector3::y())
                };
                nalgebra::Rotation3::new(axis.normalize() * std::f64::consts::PI)
            });
        let translation = n_ref.into_inner() * (t.plane.offset - ground.plane.offset);
        for k in 0..steps {
            let turn = nalgebra::Rotation3::from_axis_angle(&n_ref, k as f64 * SWEEP_STEP);
            out.push(Candidate {
                pose: isometry(&(turn * align), translation),
                free: None,
                support: 0.0,
                sweep: true,
            });
        }
    }
    out
}

/// The cells of a cubic grid that hold at least one point: a coarse, constant-time "is there a
/// point near here" for the slide search.
pub(super) struct Occupancy {
    pub(super) cell: f64,
    pub(super) cells: HashSet<[i64; 3]>,
}

impl Occupancy {
    pub(super) fn key(cell: f64, p: &Point3<f64>) -> [i64; 3] {
        // Inputs are bounded by MAX_COORDINATE; beyond i64 a float-to-int cast saturates.
        cell_key(&p.coords, cell)
    }

    pub(super) fn new(points: &[Point3<f64>], cell: f64) -> Self {
        let cells = points.iter().map(|p| Self::key(cell, p)).collect();
        Occupancy { cell, cells }
    }

    pub(super) fn share(&self, points: &[Point3<f64>]) -> f64 {
        let hits = points
            .iter()
            .filter(|p| self.cells.contains(&Self::key(self.cell, p)))
            .count();
        hits as f64 / points.len().max(1) as f64
    }
}

/// Whether `pose` puts the target within `max_translation` of the reference.
pub(super) fn in_range(pose: &Isometry3<f64>, max_translation: f64) -> bool {
    pose.translation.vector.norm() <= max_translation
}

/// What the slides score against: the reference's occupied cells and the sampled target points.
pub(super) struct SlideField {
    pub(super) occupancy: Occupancy,
    pub(super) samples: Vec<Point3<f64>>,
}

/// The slide score of `pose` moved along `free` by every multiple of [`SLIDE_STEP`] at least
/// [`SLIDE_MIN`] and at most [`SLIDE_RANGE`] away (within `max_translation`), as `(offset,
/// score)` in order of offset: the share of `samples` (target points) that land in a cell
/// holding a reference point, minus [`VIOLATION_WEIGHT`] times the share that lands in space the
/// reference saw through.
pub(super) fn slide_scores(
    pose: &Isometry3<f64>,
    free: &Vector3<f64>,
    field: &SlideField,
    image: &RangeImage,
    max_translation: f64,
) -> Vec<(f64, f64)> {
    let t = pose.translation.vector;
    let steps = (max_translation.min(SLIDE_RANGE) / SLIDE_STEP).ceil() as i64;
    (-steps..=steps)
        .map(|k| k as f64 * SLIDE_STEP)
        .filter(|offset| {
            offset.abs() >= SLIDE_MIN && (t + free * *offset).norm() <= max_translation
        })
        .map(|offset| {
            let moved = Translation3::from(free * offset) * pose;
            let agreement = field.occupancy.share(&mapped(&field.samples, &moved));
            let violations = image.count_violations(&field.samples, &moved) as f64;
            (
                offset,
                agreement - VIOLATION_WEIGHT * violations / field.samples.len().max(1) as f64,
            )
        })
        .collect()
}

/// The `count` best local maxima of the slide score of `pose` along `free`
/// ([`slide_scores`]) that score above zero, as slid poses: where a repeated structure (a
/// colonnade, a row of posts) would put the target one period off.
pub(super) fn slide_peaks(
    pose: &Isometry3<f64>,
    free: &Vector3<f64>,
    field: &SlideField,
    image: &RangeImage,
    max_translation: f64,
    count: usize,
) -> Vec<Isometry3<f64>> {
    let scores = slide_scores(pose, free, field, image, max_translation);
    let mut peaks: Vec<(f64, f64)> = scores
        .iter()
        .enumerate()
        .filter(|&(k, &(offset, score))| {
            let neighbour = |j: Option<usize>| {
                j.and_then(|j| scores.get(j))
                    .filter(|(o, _)| (o - offset).abs() < 1.5 * SLIDE_STEP)
                    .map_or(f64::NEG_INFINITY, |s| s.1)
            };
            score > 0.0 && score > neighbour(k.checked_sub(1)) && score >= neighbour(Some(k + 1))
        })
        .map(|(_, &s)| s)
        .collect();
    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    peaks
        .into_iter()
        .take(count)
        .map(|(offset, _)| Translation3::from(free * offset) * pose)
        .collect()
}

/// The slid copy of each plane-pair hypothesis (step 3 of the module docs): the pose moved along
/// its free direction by the multiple of [`SLIDE_STEP`] (at least [`SLIDE_MIN`] and at most
/// [`SLIDE_RANGE`] away, within `max_translation`) that scores best ([`slide_scores`]) on the
/// `field`: the share of sampled target points that land in a [`SLIDE_CELL`] cell holding a
/// reference point, minus [`VIOLATION_WEIGHT`] times the share that lands in space the reference
/// saw through. A pair fixes the translation only across the
/// street; its minimum-norm start is as far from the truth as the sensors are apart along it,
/// beyond the reach of ICP.
pub(super) fn slides(
    candidates: &[Candidate],
    field: &SlideField,
    image: &RangeImage,
    max_translation: f64,
) -> Vec<Candidate> {
    let best_slide = |c: &Candidate| -> Option<Candidate> {
        let free = c.free?;
        let (offset, _) = slide_scores(&c.pose, &free, field, image, max_translation)
            .into_iter()
            .reduce(|best, s| if s.1 > best.1 { s } else { best })?;
        Some(Candidate {
            pose: Translation3::from(free * offset) * c.pose,
            ..*c
        })
    };
    let slid: Vec<Candidate> = crate::par_map(candidates, best_slide)
        .into_iter()
        .flatten()
        .collect();
    // Pair hypotheses that differ only along their free direction slide to the same pose.
    deduplicate(slid)
}

pub(super) fn mapped(points: &[Point3<f64>], pose: &Isometry3<f64>) -> Vec<Point3<f64>> {
    points.iter().map(|p| pose * p).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn slide_peaks_are_the_periods_of_a_row_of_posts() {
        // Five posts 4 m apart along x, 5 m to the side of the sensor; the target sees the same
        // row. Slid by one period, four of the five posts agree; between posts, none.
        let posts: Vec<Point3<f64>> = (-2..=2)
            .flat_map(|i| {
                (0..20).map(move |k| Point3::new(4.0 * f64::from(i), 5.0, 0.1 * f64::from(k)))
            })
            .collect();
        let occupancy = Occupancy::new(&posts, SLIDE_CELL);
        let image = RangeImage::new(&posts, RangeImage::DEFAULT_RESOLUTION).unwrap();
        let field = SlideField {
            occupancy,
            samples: posts,
        };
        let peaks = slide_peaks(
            &Isometry3::identity(),
            &Vector3::x(),
            &field,
            &image,
            10.0,
            SLIDE_PEAKS,
        );
        let mut offsets: Vec<f64> = peaks.iter().map(|p| p.translation.vector.x).collect();
        offsets.sort_by(f64::total_cmp);
        assert_eq!(offsets.len(), 2);
        assert!((offsets[0] + 4.0).abs() < 1e-9 && (offsets[1] - 4.0).abs() < 1e-9);
        assert!(peaks
            .iter()
            .all(|p| p.translation.vector.yz().norm() < 1e-12));
    }

    #[test]
    fn deduplicate_equals_comparing_with_every_kept_pose() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        // Clusters of near-identical poses (within and beyond the duplicate limits) around a
        // few centres, some straddling cell boundaries.
        let mut candidates = Vec::new();
        for _ in 0..3000 {
            let centre = rng.random_range(0..6) as f64 * 0.15;
            let t = Vector3::new(
                centre + rng.random_range(-0.12..0.12),
                rng.random_range(-0.12..0.12),
                -0.05 + rng.random_range(-0.08..0.08),
            );
            let axis = Vector3::new(rng.random::<f64>(), rng.random(), rng.random())
                - Vector3::repeat(0.5);
            let angle = rng.random_range(0.0..3.0f64).to_radians();
            candidates.push(Candidate {
                pose: Isometry3::from_parts(
                    Translation3::from(t),
                    UnitQuaternion::from_scaled_axis(axis.normalize() * angle),
                ),
                free: None,
                support: 0.0,
                sweep: false,
            });
        }
        let mut brute: Vec<Isometry3<f64>> = Vec::new();
        for c in &candidates {
            if !brute
                .iter()
                .any(|d| same_pose(d, &c.pose, DUPLICATE_ANGLE, DUPLICATE_DISTANCE))
            {
                brute.push(c.pose);
            }
        }
        let fast: Vec<Isometry3<f64>> = deduplicate(candidates).iter().map(|c| c.pose).collect();
        assert!(brute.len() > 50, "{}", brute.len());
        assert_eq!(fast.len(), brute.len());
        assert!(fast == brute, "same count, different poses kept");
    }
}
