//! A reference that repeats itself: a colonnade or a row of identical boxes, whose structure
//! shifted by one period lands on itself. A result shifted by that period fits the clouds as well
//! unless the target sees what breaks the repetition, and nothing the verification ranks by (the
//! share of target points that agree) tells the two apart: a fresh colonnade of the adversarial
//! suite (repeated 21027, ten columns 3.9 m apart) came back one period off, agreeing 60 % / 71 %
//! with 0.5 % of the points in free space, the truth 61 % / 72 % with 0.6 %.

use nalgebra::{Isometry3, Point3, Translation3, Vector3};
use rustc_hash::FxHashMap;

use super::rivals::{mean_agreement_gain, TWIN_AGREEMENT_MARGIN};
use super::segment::PlaneFeature;
use super::symmetry::largest_of_directions;
use super::verify::stride_sample;
use crate::check::{CheckReport, PreparedPair, Verdict};
use crate::error::Result;
use crate::geometry::Plane;
use crate::grid::NeighbourGrid;

/// A reference point this far or more from the base plane (metres) is structure standing on it
/// (or hanging over it): what may repeat.
const STRUCTURE_HEIGHT: f64 = 0.3;
/// Planes of distinct directions along which periods are sought ([`base_planes`]).
const BASE_PLANES: usize = 3;
/// Fewest structure points for a period to be sought.
const MIN_STRUCTURE: usize = 100;
/// Structure points (at most, by a fixed stride) whose pairwise differences propose periods and
/// that test them.
const STRUCTURE_SAMPLES: usize = 400;
/// Periods sought (metres, along the base plane).
const PERIOD_RANGE: (f64, f64) = (1.0, 12.0);
/// Two structure points propose their difference as a period only when they stand at the same
/// height over the base plane, within this (metres).
const SAME_LEVEL: f64 = 0.3;
/// A shifted result keeps the free space as clear when it puts at most this share more of the
/// points there.
const PERIOD_FREE_MARGIN: f64 = 0.005;
/// Cell side (metres) of the histogram of the proposed periods.
const PERIOD_BIN: f64 = 0.25;
/// Proposals (the histogram's strongest peaks) tested as periods.
const PEAKS: usize = 4;
/// A shifted structure point lands on the structure when one lies within this (metres).
const LANDING: f64 = 0.15;
/// A shift is a period when, of the structure that does not land on itself shifted by half of it
/// (a wall lands on itself shifted by any length along it, a colonnade only by its period), at
/// least this share lands shifted by all of it ...
const MIN_REPEATING_SHARE: f64 = 0.5;
/// ... and that is at least this share of all the structure.
const MIN_REPEATING: f64 = 0.05;
/// Cell side (metres) of the grid the landings are looked up in.
pub(super) const LANDING_CELL: f64 = 0.3;
/// A proposed period is refined along it and across it in the plane, each way this many steps of
/// [`REFINE_STEP`] (metres), then one step of half that either side of the best.
const REFINE_STEPS: i64 = 3;
const REFINE_STEP: f64 = 0.1;
/// Structure samples (at most, a stride of the test's) that the refinement counts landings of.
const REFINE_SAMPLES: usize = 100;

/// The planes along which [`periods`] are sought: the largest of each of the three largest
/// directions (a ground, a wall, a box's side), since the ground need not be the largest plane
/// of a scan (a unit on its side, a box close by).
pub(super) fn base_planes(features: &[PlaneFeature]) -> Vec<Plane> {
    largest_of_directions(features, BASE_PLANES)
        .into_iter()
        .map(|f| f.plane)
        .collect()
}

/// The periods of the reference's structure along a base plane `plane` (its ground, usually):
/// shifts (reference frame, within [`PERIOD_RANGE`]) under which most of the structure that does
/// not land on itself shifted by half the shift lands on itself ([`MIN_REPEATING_SHARE`], and at
/// least [`MIN_REPEATING`] of all of it). Proposed by the strongest peaks of the histogram of the
/// differences between structure points at one level, each refined to the nearby shift that lands
/// the most. A share of the structure that does not land at half the shift, not of all of it: a
/// long wall behind a row of boxes lands on itself at any shift along it, and when the wall is
/// most of the structure (repeated 22082, 22145) the boxes that repeat are a small part of it.
///
/// `grid` indexes `points` (cells of [`LANDING_CELL`]): it is built once for the base planes of a
/// cloud, each of which keeps its own structure.
pub(super) fn periods(
    points: &[Point3<f64>],
    grid: &NeighbourGrid,
    plane: &Plane,
) -> Vec<Vector3<f64>> {
    let standing: Vec<bool> = points
        .iter()
        .map(|p| plane.signed_distance(p).abs() >= STRUCTURE_HEIGHT)
        .collect();
    let structure: Vec<Point3<f64>> = points
        .iter()
        .zip(&standing)
        .filter(|(_, s)| **s)
        .map(|(p, _)| *p)
        .collect();
    if structure.len() < MIN_STRUCTURE {
        return Vec::new();
    }
    let samples = stride_sample(&structure, STRUCTURE_SAMPLES);
    let n = plane.normal.into_inner();
    let u = n.cross(&Vector3::x());
    let u = if u.norm() > 0.5 {
        u.normalize()
    } else {
        n.cross(&Vector3::y()).normalize()
    };
    let v = n.cross(&u);
    // The histogram of the differences, each counted once (the sign making its first in-plane
    // coordinate positive): per cell, the count and the sum of the differences.
    let mut bins: FxHashMap<(i64, i64), (usize, Vector3<f64>)> = FxHashMap::default();
    for (i, p) in samples.iter().enumerate() {
        for q in samples.iter().skip(i + 1) {
            let d = q - p;
            if d.dot(&n).abs() > SAME_LEVEL {
                continue;
            }
            let (a, b) = (d.dot(&u), d.dot(&v));
            let length = a.hypot(b);
            if !(PERIOD_RANGE.0..=PERIOD_RANGE.1).contains(&length) {
                continue;
            }
            let (d, a, b) = if a < 0.0 || (a == 0.0 && b < 0.0) {
                (-d, -a, -b)
            } else {
                (d, a, b)
            };
            let cell = (
                (a / PERIOD_BIN).floor() as i64,
                (b / PERIOD_BIN).floor() as i64,
            );
            let bin = bins.entry(cell).or_insert((0, Vector3::zeros()));
            bin.0 += 1;
            bin.1 += d - n * d.dot(&n);
        }
    }
    // Peaks: each cell with its eight neighbours, strongest first, no two within two cells.
    let around = |(x, y): (i64, i64)| {
        let mut sum = (0usize, Vector3::zeros());
        for dx in -1..=1 {
            for dy in -1..=1 {
                if let Some((c, s)) = bins.get(&(x + dx, y + dy)) {
                    sum.0 += c;
                    sum.1 += s;
                }
            }
        }
        sum
    };
    let mut ranked: Vec<((i64, i64), usize, Vector3<f64>)> = bins
        .keys()
        .map(|&cell| {
            let (count, sum) = around(cell);
            (cell, count, sum / count.max(1) as f64)
        })
        .collect();
    ranked.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    let mut peaks: Vec<((i64, i64), Vector3<f64>)> = Vec::with_capacity(PEAKS);
    for (cell, _, shift) in ranked {
        if peaks.len() == PEAKS {
            break;
        }
        if peaks
            .iter()
            .all(|(c, _)| (c.0 - cell.0).abs() > 2 || (c.1 - cell.1).abs() > 2)
        {
            peaks.push((cell, shift));
        }
    }
    // Per point of `of`, whether it lands on the structure shifted by `shift` either way.
    let on_structure = |i: usize| standing.get(i).copied().unwrap_or(false);
    let lands = |of: &[Point3<f64>], shift: &Vector3<f64>| -> Vec<bool> {
        of.iter()
            .map(|p| {
                grid.any_within_where(&(*p + shift), LANDING, on_structure)
                    || grid.any_within_where(&(*p - shift), LANDING, on_structure)
            })
            .collect()
    };
    let few = stride_sample(&samples, REFINE_SAMPLES);
    let count = |shift: &Vector3<f64>| lands(&few, shift).into_iter().filter(|l| *l).count();
    // The shift near `seed` (along it, then across it in the plane) that lands the most samples:
    // a cell's mean difference may be a decimetre or two off the period (a wall behind a
    // colonnade spreads differences evenly over the cell). Coarse steps, then half steps.
    let refine = |seed: Vector3<f64>| -> Vector3<f64> {
        let along = seed.normalize();
        let across = n.cross(&along);
        let mut best = seed;
        let mut most = count(&best);
        for direction in [along, across] {
            for (steps, step) in [(REFINE_STEPS, REFINE_STEP), (1, 0.5 * REFINE_STEP)] {
                let start = best;
                for k in (-steps..=steps).filter(|k| *k != 0) {
                    let shift = start + direction * (k as f64 * step);
                    let c = count(&shift);
                    if c > most {
                        (most, best) = (c, shift);
                    }
                }
            }
        }
        best
    };
    peaks
        .into_iter()
        .map(|(_, seed)| refine(seed))
        .filter(|shift| {
            // The samples that do not land shifted by half the period (a wall or a box's side
            // along the shift lands on itself shifted by any length): of those, the share that
            // lands shifted by the whole period.
            let (whole, half) = (lands(&samples, shift), lands(&samples, &(shift * 0.5)));
            let free = half.iter().filter(|h| !**h).count();
            let repeating = whole.iter().zip(&half).filter(|(w, h)| **w && !**h).count();
            let n = samples.len() as f64;
            repeating as f64 >= MIN_REPEATING * n
                && repeating as f64 >= MIN_REPEATING_SHARE * free as f64
        })
        .collect()
}

/// A result `pose` (whose check is `report`) shifted by one of the reference's `periods` either
/// way, settled by the check's re-alignment and still at least half a period from the result,
/// that the check cannot tell from it: it passes the check, agrees on its overlap within
/// [`TWIN_AGREEMENT_MARGIN`] of the result on average over the two ways and puts at most
/// [`PERIOD_FREE_MARGIN`] more of the points into free space. A correct colonnade whose odd box
/// both sensors see (repeated 116) had a shift agreeing -1 / -11 points against it. The shift
/// and the settled shifted pose's check.
pub(super) fn period_twin(
    pose: &Isometry3<f64>,
    report: &CheckReport,
    periods: &[Vector3<f64>],
    pair: &PreparedPair,
) -> Result<Option<(Vector3<f64>, CheckReport)>> {
    for period in periods {
        for shift in [*period, -period] {
            // Settled by the check's re-alignment first: the period is refined on a 5 cm
            // lattice and the result itself may be a few centimetres off. One that slides back
            // towards the result is no twin.
            let shifted = pair.aligned(&(Translation3::from(shift) * pose))?;
            let moved = (shifted.translation.vector - pose.translation.vector).norm();
            if moved < 0.5 * shift.norm() {
                continue;
            }
            let c = pair.check(&shifted)?;
            // The two ways' agreement within TWIN_AGREEMENT_MARGIN on average (a shift along a
            // row trades one end of it for the other, so one way may gain what the other
            // loses), and the free space as clear within half a point.
            let twin = c.verdict == Verdict::Consistent
                && mean_agreement_gain(report, &c) >= -TWIN_AGREEMENT_MARGIN
                && c.free_share() <= report.free_share() + PERIOD_FREE_MARGIN;
            if twin {
                return Ok(Some((shift, c)));
            }
        }
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`periods`] of `points` along `plane`, with their grid.
    fn periods_of(points: &[Point3<f64>], plane: &Plane) -> Vec<Vector3<f64>> {
        periods(points, &NeighbourGrid::new(points, LANDING_CELL), plane)
    }

    /// Ground points on a 10 cm lattice over `[-x, x] x [-y, y]`.
    fn ground(x: f64, y: f64) -> Vec<Point3<f64>> {
        let mut points = Vec::new();
        let (nx, ny) = ((x / 0.1) as i64, (y / 0.1) as i64);
        for i in -nx..=nx {
            for j in -ny..=ny {
                points.push(Point3::new(i as f64 * 0.1, j as f64 * 0.1, 0.0));
            }
        }
        points
    }

    /// The surface of a square column of side 0.4 m at `(x, y)`, 3 m high.
    fn column(x: f64, y: f64) -> Vec<Point3<f64>> {
        let mut points = Vec::new();
        for k in 0..30 {
            let z = 0.35 + 0.1 * k as f64;
            for s in 0..5 {
                let t = -0.2 + 0.1 * s as f64;
                for (dx, dy) in [(t, -0.2), (t, 0.2), (-0.2, t), (0.2, t)] {
                    points.push(Point3::new(x + dx, y + dy, z));
                }
            }
        }
        points
    }

    #[test]
    fn a_colonnade_repeats_and_a_wall_does_not() {
        let plane = Plane::new(Vector3::z(), 0.0).unwrap();
        // Eight columns 3.9 m apart along a line 20 degrees off the x axis.
        let along = Vector3::new(20f64.to_radians().cos(), 20f64.to_radians().sin(), 0.0);
        let mut colonnade = ground(15.0, 15.0);
        for k in 0..8 {
            let c = along * (3.9 * (k as f64 - 3.5)) + Vector3::new(0.0, 2.0, 0.0);
            colonnade.extend(column(c.x, c.y));
        }
        let found = periods_of(&colonnade, &plane);
        assert!(!found.is_empty());
        let period = found[0];
        assert!((period.norm() - 3.9).abs() < 0.1, "{period}");
        assert!(period.normalize().dot(&along).abs() > 0.999, "{period}");
        assert!(period.z.abs() < 1e-9);
        // A long wall lands on itself shifted by any length along it: no period.
        let mut wall = ground(15.0, 15.0);
        for i in -140..=140 {
            for k in 0..30 {
                wall.push(Point3::new(i as f64 * 0.1, 6.0, 0.35 + 0.1 * k as f64));
            }
        }
        assert!(periods_of(&wall, &plane).is_empty());
        // One column: nothing to repeat.
        let mut one = ground(15.0, 15.0);
        one.extend(column(-3.0, 1.0));
        assert!(periods_of(&one, &plane).is_empty());
        // Two identical columns 5 m apart repeat once.
        one.extend(column(1.0, -2.0));
        let found = periods_of(&one, &plane);
        assert!((found[0].norm() - 5.0).abs() < 0.1, "{found:?}");
        // Ground alone: nothing to repeat.
        assert!(periods_of(&ground(5.0, 5.0), &plane).is_empty());
    }

    #[test]
    fn a_row_before_a_long_wall_repeats() {
        // A wall 28 m long and 6 m high behind three columns 4.5 m apart: the columns are about a
        // tenth of the structure, and the wall lands on itself at any shift along it.
        let plane = Plane::new(Vector3::z(), 0.0).unwrap();
        let mut scene = ground(15.0, 15.0);
        for i in -140..=140 {
            for k in 0..60 {
                scene.push(Point3::new(i as f64 * 0.1, 6.0, 0.35 + 0.1 * k as f64));
            }
        }
        for k in -1..=1 {
            scene.extend(column(4.5 * k as f64, 2.0));
        }
        let found = periods_of(&scene, &plane);
        assert!(!found.is_empty());
        assert!((found[0].norm() - 4.5).abs() < 0.1, "{found:?}");
        assert!(
            found[0].normalize().dot(&Vector3::x()).abs() > 0.999,
            "{found:?}"
        );
    }
}
