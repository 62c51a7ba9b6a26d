//! The scene's own half-turn symmetries (a corridor or room turned about its axes), probed around
//! the best pose: a rival the hypotheses may never reach.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use super::segment::PlaneFeature;
use super::verify::DISTINCT_DISTANCE;
use crate::geometry::Plane;

/// Largest reference planes whose normals (and the lines they share) give the half turns of
/// [`half_turns`].
pub(super) const SYMMETRY_PLANES: usize = 3;
/// Two planes share a line for [`half_turns`] when their normals are at least this far from
/// parallel (the sine of the angle between them, ~12 degrees).
pub(super) const MIN_AXIS_NORM: f64 = 0.2;
/// Axes closer than this (the cosine of 10 degrees) are one.
pub(super) const SAME_AXIS_COSINE: f64 = 0.985;

/// The largest reference planes of three directions make a square corner for [`third_turns`]
/// when no two of their normals are further than this from perpendicular (the cosine of 70
/// degrees).
pub(super) const MAX_CORNER_COSINE: f64 = 0.34;
/// ... and a truly square corner when none is further than this (the cosine of 85 degrees): a
/// third turn maps its planes onto one another within the noise, so only what lies beyond the
/// corner tells the turns apart (see `half_turn_rival`).
pub(super) const SQUARE_CORNER_COSINE: f64 = 0.087;

/// Adds the direction of `a` to `axes` unless it is too short (a cross product of two planes
/// within ~12 degrees of parallel, [`MIN_AXIS_NORM`]) or within 10 degrees of one already there.
pub(super) fn add_axis(axes: &mut Vec<Vector3<f64>>, a: Vector3<f64>) {
    let norm = a.norm();
    if norm > MIN_AXIS_NORM
        && axes
            .iter()
            .all(|b| (a.dot(b) / norm).abs() < SAME_AXIS_COSINE)
    {
        axes.push(a / norm);
    }
}

/// Unit normals of the [`SYMMETRY_PLANES`] largest reference planes.
pub(super) fn largest_normals(features: &[PlaneFeature]) -> Vec<Vector3<f64>> {
    features
        .iter()
        .take(SYMMETRY_PLANES)
        .map(|f| f.plane.normal.into_inner())
        .collect()
}

/// Unit directions of the lines planes of these `normals` share, two by two ([`add_axis`]).
pub(super) fn shared_lines(normals: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
    let mut lines = Vec::new();
    for (i, a) in normals.iter().enumerate() {
        for b in normals.iter().skip(i + 1) {
            add_axis(&mut lines, a.cross(b));
        }
    }
    lines
}

/// Half turns about the axes of the largest reference planes (their normals and the lines two of
/// them share, [`SYMMETRY_PLANES`] planes), each through the centroid of the reference points and
/// through their middle ([`middle`], when it lies [`DISTINCT_DISTANCE`] or more away): the
/// symmetries a corridor, a room or a box would have. A corridor turned about its axis is the
/// same box (floor onto ceiling, walls swapped), and when the two sensors' fields of view differ
/// the hypotheses of the truth rank below those of the flip and may never be verified: a 16-beam
/// unit turned upside down put 80 % of its points near the 32-beam reference, the truth 61 %. A
/// room's own centre is its middle, not the centroid, which leans toward the walls the sensor
/// sees best: two rooms turned about the vertical came back 180 degrees off while the turns
/// through the centroid settled metres away. Each turn, applied to the best pose and settled by
/// ICP, is one more runner-up.
pub(super) fn half_turns(features: &[PlaneFeature], points: &[Point3<f64>]) -> Vec<Isometry3<f64>> {
    let normals = largest_normals(features);
    let mut directions = Vec::new();
    for n in &normals {
        add_axis(&mut directions, *n);
    }
    let mut axes = directions.clone();
    for a in shared_lines(&normals) {
        add_axis(&mut axes, a);
    }
    let centroid = centroid(points);
    let mid = middle(points, &directions, centroid);
    let mut centres = vec![centroid];
    if (mid - centroid).norm() >= DISTINCT_DISTANCE {
        centres.push(mid);
    }
    centres
        .iter()
        .flat_map(|centre| {
            axes.iter().map(move |axis| {
                turn_about(&Unit::new_unchecked(*axis), std::f64::consts::PI, centre)
            })
        })
        .collect()
}

/// The turn by `angle` (radians) about the line through `through` along `axis`.
fn turn_about(axis: &Unit<Vector3<f64>>, angle: f64, through: &Vector3<f64>) -> Isometry3<f64> {
    let rotation = UnitQuaternion::from_axis_angle(axis, angle);
    Isometry3::from_parts(Translation3::from(through - rotation * through), rotation)
}

/// The centroid of `points` (the origin for none).
fn centroid(points: &[Point3<f64>]) -> Vector3<f64> {
    points
        .iter()
        .fold(Vector3::zeros(), |sum, p| sum + p.coords)
        / points.len().max(1) as f64
}

/// Half turns that swap two of the largest reference planes of distinct directions
/// ([`largest_of_directions`], [`SYMMETRY_PLANES`] of them): about each bisector of their normals
/// (the sum and the difference), through the point of the line the two planes share nearest to
/// the centroid of the reference points. A floor and a wall turned onto each other are the same
/// dihedral, and a unit on its side sees either as a fan of scan lines: a fresh furnished room of
/// the adversarial suite (corridor 180157, a 16-beam target on its side) came back turned 180
/// degrees about the bisector of the floor's and a wall's normals, 1.6 m off, overlapping 79 %
/// against the truth's 64 % with 1.9 % of the points in free space against none.
pub(super) fn swap_turns(features: &[PlaneFeature], points: &[Point3<f64>]) -> Vec<Isometry3<f64>> {
    let chosen = largest_of_directions(features, SYMMETRY_PLANES);
    let centroid = centroid(points);
    let mut turns = Vec::new();
    for (i, a) in chosen.iter().enumerate() {
        for b in chosen.iter().skip(i + 1) {
            let (na, nb) = (a.plane.normal.into_inner(), b.plane.normal.into_inner());
            let line = na.cross(&nb);
            if line.norm() < MIN_AXIS_NORM {
                continue;
            }
            // The plane through the centroid across the shared line meets it there.
            let Ok(across) = Plane::new(line, -line.dot(&centroid)) else {
                continue;
            };
            let Some(at) = Plane::common_point(&[a.plane, b.plane, across]) else {
                continue;
            };
            for axis in [na + nb, na - nb] {
                turns.push(turn_about(
                    &Unit::new_normalize(axis),
                    std::f64::consts::PI,
                    &at.coords,
                ));
            }
        }
    }
    turns
}

/// Turns of a third (120 degrees either way) about the four diagonals of a square corner, through
/// the point where its three planes meet, when the largest reference planes of three directions
/// (each more than 10 degrees from the others) make one (no two normals further than `max_cosine`
/// from perpendicular: [`MAX_CORNER_COSINE`] or [`SQUARE_CORNER_COSINE`]); none otherwise.
/// Such a turn maps the corner's three planes onto one another: a cube corner matched plane for plane in the wrong cyclic order. Seen by
/// one sensor on its side, a fresh corner of the adversarial suite (corner 9066, walls 90.7
/// degrees apart) came back turned 120 degrees and 2.5 m off, passing the check with 18.6 % of
/// its points in free space; the truth, a third turn of it, puts 3.0 % there.
pub(super) fn third_turns(features: &[PlaneFeature], max_cosine: f64) -> Vec<Isometry3<f64>> {
    // The largest planes of three directions: a plane parallel to a larger one (a pavement
    // beside the road, the face of a box before a wall) is another surface of the same side of
    // the corner. Of a fresh corner seen by a sensor on its side (adversarial 11070, returned
    // turned 120 degrees) the third largest reference plane lay parallel to the second.
    let chosen = largest_of_directions(features, 3);
    let [fa, fb, fc] = chosen[..] else {
        return Vec::new();
    };
    let planes = [fa.plane, fb.plane, fc.plane];
    let [a, b, c] = planes.map(|p| p.normal.into_inner());
    if a.dot(&b).abs().max(a.dot(&c).abs()).max(b.dot(&c).abs()) > max_cosine {
        return Vec::new();
    }
    let Some(corner) = Plane::common_point(&planes) else {
        return Vec::new();
    };
    let corner = corner.coords;
    let mut turns = Vec::with_capacity(8);
    for (sb, sc) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
        let axis = Unit::new_normalize(a + b * sb + c * sc);
        for angle in [2.0, -2.0].map(|k| k * std::f64::consts::FRAC_PI_3) {
            turns.push(turn_about(&axis, angle, &corner));
        }
    }
    turns
}

/// The largest planes of at most `count` directions (each more than 10 degrees from the others),
/// largest first.
pub(super) fn largest_of_directions(features: &[PlaneFeature], count: usize) -> Vec<&PlaneFeature> {
    let mut chosen: Vec<&PlaneFeature> = Vec::with_capacity(count);
    for f in features {
        if chosen.len() == count {
            break;
        }
        let n = f.plane.normal;
        if chosen
            .iter()
            .all(|c| c.plane.normal.dot(&n).abs() < SAME_AXIS_COSINE)
        {
            chosen.push(f);
        }
    }
    chosen
}

/// `start` moved, along each unit direction in turn, to the midpoint of the 2nd and 98th
/// percentiles of the points' projections on it: the middle of a room or a corridor along the
/// normals of its walls, floor and ceiling (exact for orthogonal directions).
pub(super) fn middle(
    points: &[Point3<f64>],
    directions: &[Vector3<f64>],
    start: Vector3<f64>,
) -> Vector3<f64> {
    let mut centre = start;
    if points.is_empty() {
        return centre;
    }
    let mut projections = vec![0.0; points.len()];
    for d in directions {
        for (value, p) in projections.iter_mut().zip(points) {
            *value = d.dot(&p.coords);
        }
        projections.sort_by(f64::total_cmp);
        let at = |q: f64| projections[((projections.len() - 1) as f64 * q).round() as usize];
        let mid = 0.5 * (at(0.02) + at(0.98));
        centre += d * (mid - d.dot(&centre));
    }
    centre
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Plane;

    #[test]
    fn middle_is_the_centre_of_a_room_seen_mostly_on_one_side() {
        // Walls at x = 0 and x = 10 (y from 0 to 4): nine points in ten on the near wall.
        let mut points = Vec::new();
        for i in 0..1000 {
            let y = 4.0 * (i % 100) as f64 / 100.0;
            let x = if i % 10 == 0 { 10.0 } else { 0.0 };
            points.push(Point3::new(x, y, 1.5));
        }
        let centroid = points.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / 1000.0;
        assert!((centroid.x - 1.0).abs() < 1e-9);
        let mid = middle(&points, &[Vector3::x(), Vector3::y()], centroid);
        assert!((mid.x - 5.0).abs() < 1e-9, "{mid}");
        assert!((mid.y - 1.98).abs() < 0.05, "{mid}");
        assert_eq!(mid.z, centroid.z);
        assert_eq!(middle(&[], &[Vector3::x()], centroid), centroid);
    }

    /// A plane feature of unit extent with this normal and offset.
    fn feature(normal: Vector3<f64>, offset: f64) -> PlaneFeature {
        PlaneFeature {
            plane: Plane::new(normal, offset).unwrap(),
            voxels: Vec::new(),
            centroid: Point3::origin(),
            extent: [1.0, 1.0],
        }
    }

    #[test]
    fn half_turns_are_the_box_symmetries_about_the_centroid() {
        // A floor and two walls 60 degrees apart: three normals and three shared lines, of which
        // the floor's normal and the walls' shared line (vertical) are one axis.
        let wall = Vector3::new(60f64.to_radians().cos(), 60f64.to_radians().sin(), 0.0);
        let features = [
            feature(Vector3::z(), 1.0),
            feature(Vector3::x(), 1.0),
            feature(wall, 1.0),
        ];
        assert_eq!(shared_lines(&largest_normals(&features)).len(), 3);
        let points = [Point3::new(1.0, 2.0, 0.0), Point3::new(3.0, 0.0, 2.0)];
        let turns = half_turns(&features, &points);
        assert_eq!(turns.len(), 5);
        let centre = Point3::new(2.0, 1.0, 1.0);
        for turn in &turns {
            assert!((turn.rotation.angle() - std::f64::consts::PI).abs() < 1e-9);
            assert!((turn * centre - centre).norm() < 1e-9);
            assert!((turn * turn).translation.vector.norm() < 1e-9);
        }
    }

    #[test]
    fn swap_turns_map_each_pair_of_planes_onto_each_other() {
        // A floor at z = -1.5, a wall at x = 4 and a wall 80 degrees from it through (4, 6, 0),
        // and a ceiling parallel to the floor (passed over: one direction).
        let at = Vector3::new(4.0, 6.0, 0.0);
        let skew = Vector3::new(80f64.to_radians().cos(), 80f64.to_radians().sin(), 0.0);
        let features = [
            feature(Vector3::z(), 1.5),
            feature(Vector3::z(), -2.5),
            feature(Vector3::x(), -4.0),
            feature(skew, -skew.dot(&at)),
        ];
        let points = [Point3::new(1.0, 2.0, 0.0), Point3::new(3.0, 0.0, 2.0)];
        let turns = swap_turns(&features, &points);
        // Three pairs of directions, two bisectors each.
        assert_eq!(turns.len(), 6);
        let planes = [features[0].plane, features[2].plane, features[3].plane];
        let pairs = [(0, 1), (0, 1), (0, 2), (0, 2), (1, 2), (1, 2)];
        for (turn, (i, j)) in turns.iter().zip(pairs) {
            assert!((turn.rotation.angle() - std::f64::consts::PI).abs() < 1e-9);
            // A point of plane i lands on plane j, and the reverse.
            for (a, b) in [(planes[i], planes[j]), (planes[j], planes[i])] {
                let on_a = Point3::from(-a.offset * a.normal.into_inner());
                assert!(b.signed_distance(&(turn * on_a)).abs() < 1e-9);
            }
        }
        // Parallel planes only: nothing to swap.
        assert!(swap_turns(&features[..2], &points).is_empty());
    }

    #[test]
    fn third_turns_permute_a_square_corners_planes() {
        // A corner at (2, -1, 3), its planes slightly off square (88 degrees between two walls).
        let corner = Point3::new(2.0, -1.0, 3.0);
        let wall = Vector3::new(88f64.to_radians().cos(), 88f64.to_radians().sin(), 0.0);
        let normals = [Vector3::x(), wall, Vector3::z()];
        let features = normals.map(|n| feature(n, -n.dot(&corner.coords)));
        let turns = third_turns(&features, MAX_CORNER_COSINE);
        assert_eq!(turns.len(), 8);
        // 88 degrees is a square corner too (within 5 degrees); 80 degrees is not.
        assert_eq!(third_turns(&features, SQUARE_CORNER_COSINE).len(), 8);
        let eighty = Vector3::new(80f64.to_radians().cos(), 80f64.to_radians().sin(), 0.0);
        let mut skewed = features.clone();
        skewed[1] = feature(eighty, -eighty.dot(&corner.coords));
        assert_eq!(third_turns(&skewed, MAX_CORNER_COSINE).len(), 8);
        assert!(third_turns(&skewed, SQUARE_CORNER_COSINE).is_empty());
        for turn in &turns {
            assert!((turn.rotation.angle() - 2.0 * std::f64::consts::FRAC_PI_3).abs() < 1e-9);
            // The corner stays put.
            assert!((turn * corner - corner).norm() < 1e-9);
            // Each plane's normal lands within 2 degrees of another plane's (either sign).
            for n in &normals {
                let m = turn.rotation * n;
                let best = normals.iter().map(|o| m.dot(o).abs()).fold(0.0, f64::max);
                assert!(best > 2f64.to_radians().cos(), "{m}");
                assert!(m.dot(n).abs() < 0.1, "a third turn moves every plane");
            }
        }
        // Walls 60 degrees apart make no square corner: no third turns.
        let skew = Vector3::new(0.5, 60f64.to_radians().sin(), 0.0);
        assert!(third_turns(
            &[
                feature(Vector3::x(), 0.0),
                feature(skew, 0.0),
                feature(Vector3::z(), 0.0)
            ],
            MAX_CORNER_COSINE
        )
        .is_empty());
        // Fewer than three planes: none either.
        assert!(third_turns(&features[..2], MAX_CORNER_COSINE).is_empty());
        // A plane parallel to a larger one (a pavement beside the road) is passed over for the
        // next direction: the same corner, the same turns.
        let pavement = feature(Vector3::z(), -Vector3::z().dot(&corner.coords) + 0.15);
        let with_pavement = [
            features[2].clone(),
            pavement.clone(),
            features[0].clone(),
            features[1].clone(),
        ];
        let again = third_turns(&with_pavement, MAX_CORNER_COSINE);
        assert_eq!(again.len(), 8);
        for turn in &again {
            assert!((turn * corner - corner).norm() < 1e-9);
        }
        // Only two directions among the planes: none.
        assert!(third_turns(
            &[features[0].clone(), pavement, features[2].clone()],
            MAX_CORNER_COSINE
        )
        .is_empty());
    }
}
