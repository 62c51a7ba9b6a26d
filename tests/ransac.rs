//! RANSAC for planes and lines: accuracy against ground truth, the joint refinement of
//! `extract_planes`, determinism across thread counts, and errors on bad input.

mod common;

use common::{corner_cloud, normal_error_deg};
use lidarcal::geometry::Line;
use lidarcal::ransac::line::ransac_line;
use lidarcal::ransac::plane::{extract_planes, ransac_plane, ExtractOptions};
use lidarcal::ransac::RansacOptions;
use lidarcal::Error;
use nalgebra::{Point3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

#[test]
fn single_plane_is_accurate_in_clutter() {
    let (points, planes) = corner_cloud(3000, 2250, 0.03, 1); // 20 % clutter
    let found = ransac_plane(&points, &RansacOptions::new(0.09)).unwrap();
    let best = planes
        .iter()
        .map(|p| normal_error_deg(&p.normal, &found.model.normal))
        .fold(f64::INFINITY, f64::min);
    assert!(best < 1.0, "normal error {best} deg");
    assert!(
        found.inliers.len() >= 2500,
        "{} inliers",
        found.inliers.len()
    );
    // Normal toward the sensor at the origin.
    assert!(found.model.offset > 0.0);
    // Inliers are exactly the points within the threshold of the returned model.
    for (i, p) in points.iter().enumerate() {
        let inside = found.model.signed_distance(p).abs() < 0.09;
        assert_eq!(inside, found.inliers.binary_search(&i).is_ok());
    }
}

#[test]
fn extract_planes_recovers_corner_within_a_tenth_of_a_degree() {
    let (points, planes) = corner_cloud(3000, 2250, 0.03, 2);
    let found = extract_planes(&points, &ExtractOptions::new(3, 0.09)).unwrap();
    assert_eq!(found.len(), 3);
    assert!(found
        .windows(2)
        .all(|w| w[0].inliers.len() >= w[1].inliers.len()));
    for truth in &planes {
        let err = found
            .iter()
            .map(|f| normal_error_deg(&truth.normal, &f.plane.normal))
            .fold(f64::INFINITY, f64::min);
        assert!(err < 0.1, "normal error {err} deg");
    }
    // No point belongs to two planes.
    let mut all: Vec<usize> = found
        .iter()
        .flat_map(|f| f.inliers.iter().copied())
        .collect();
    let total = all.len();
    all.sort_unstable();
    all.dedup();
    assert_eq!(all.len(), total);
}

#[test]
fn a_third_wall_in_the_span_of_two_is_passed_over_for_the_floor() {
    // Three large vertical walls (their normals share a plane: no corner) and a smaller floor.
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut points = Vec::new();
    let mut patch = |n: usize, f: &dyn Fn(f64, f64) -> Point3<f64>, rng: &mut ChaCha8Rng| {
        for _ in 0..n {
            let (u, v) = (rng.random_range(0.0..1.0), rng.random_range(0.0..1.0));
            let noise = rng.random_range(-0.01..0.01);
            let p = f(u, v);
            points.push(Point3::new(p.x + noise, p.y + noise, p.z + noise));
        }
    };
    patch(
        3000,
        &|u, v| Point3::new(6.0, -8.0 + 16.0 * u, -1.5 + 6.0 * v),
        &mut rng,
    );
    patch(
        2500,
        &|u, v| Point3::new(-8.0 + 14.0 * u, 7.0, -1.5 + 6.0 * v),
        &mut rng,
    );
    // A far wall at 45 degrees to both.
    patch(
        2000,
        &|u, v| Point3::new(-6.0 + 6.0 * u, -9.0 + 6.0 * u, -1.5 + 6.0 * v),
        &mut rng,
    );
    patch(
        800,
        &|u, v| Point3::new(-4.0 + 8.0 * u, -4.0 + 8.0 * v, -1.5),
        &mut rng,
    );
    let options = ExtractOptions::new(3, 0.05);
    let plain = extract_planes(&points, &options).unwrap();
    assert!(
        plain.iter().all(|p| p.plane.normal.z.abs() < 0.1),
        "without the rule the three walls are taken"
    );
    let found = extract_planes(
        &points,
        &ExtractOptions {
            min_angle_between: Some(20f64.to_radians()),
            ..options
        },
    )
    .unwrap();
    let floors = found
        .iter()
        .filter(|p| p.plane.normal.z.abs() > 0.99)
        .count();
    assert_eq!(
        floors,
        1,
        "{:?}",
        found.iter().map(|p| p.plane.normal).collect::<Vec<_>>()
    );
}

#[test]
fn joint_refinement_removes_the_sequential_tilt() {
    // Noisier walls and a wide threshold, as in the planar seed's protocol: sequential extraction
    // gives the first planes their neighbours' points near the intersection lines.
    let mut seq_total = 0.0;
    let mut joint_total = 0.0;
    for seed in 0..5 {
        let (points, planes) = corner_cloud(2500, 0, 0.05, 100 + seed);
        let mut options = ExtractOptions::new(3, 0.15);
        options.ransac.seed = seed;
        let joint = extract_planes(&points, &options).unwrap();
        options.refinement_rounds = 0;
        let sequential = extract_planes(&points, &options).unwrap();
        for truth in &planes {
            let err = |set: &[lidarcal::ransac::plane::ExtractedPlane]| {
                set.iter()
                    .map(|f| normal_error_deg(&truth.normal, &f.plane.normal))
                    .fold(f64::INFINITY, f64::min)
            };
            seq_total += err(&sequential);
            joint_total += err(&joint);
        }
    }
    let (seq_mean, joint_mean) = (seq_total / 15.0, joint_total / 15.0);
    eprintln!("mean normal error: sequential {seq_mean:.4} deg, joint {joint_mean:.4} deg");
    assert!(
        joint_mean < 0.5 * seq_mean,
        "sequential {seq_mean}, joint {joint_mean}"
    );
}

#[test]
fn results_are_bit_identical_across_thread_counts() {
    let (points, _) = corner_cloud(20_000, 5000, 0.03, 3);
    let options = ExtractOptions::new(3, 0.09);
    let one = in_pool(1, || extract_planes(&points, &options).unwrap());
    let two = in_pool(2, || extract_planes(&points, &options).unwrap());
    let four = in_pool(4, || extract_planes(&points, &options).unwrap());
    assert_eq!(one, two);
    assert_eq!(one, four);
    let single_1 = in_pool(1, || {
        ransac_plane(&points, &RansacOptions::new(0.05)).unwrap()
    });
    let single_2 = in_pool(2, || {
        ransac_plane(&points, &RansacOptions::new(0.05)).unwrap()
    });
    assert_eq!(single_1, single_2);
}

#[test]
fn line_in_clutter() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let truth = Line::new(Point3::new(3.0, -1.0, 0.0), Vector3::new(0.1, 0.05, 1.0)).unwrap();
    let mut points: Vec<Point3<f64>> = (0..300)
        .map(|_| {
            let s: f64 = rng.random_range(-1.0..2.0);
            let jitter = Vector3::new(
                common::gaussian(&mut rng),
                common::gaussian(&mut rng),
                common::gaussian(&mut rng),
            ) * 0.005;
            truth.point + truth.direction.into_inner() * s + jitter
        })
        .collect();
    points.extend((0..700).map(|_| {
        Point3::new(
            rng.random_range(0.0..6.0),
            rng.random_range(-3.0..3.0),
            rng.random_range(-1.0..2.0),
        )
    }));
    let found = ransac_line(&points, &RansacOptions::new(0.02)).unwrap();
    let err = normal_error_deg(&truth.direction, &found.model.direction);
    assert!(err < 0.5, "direction error {err} deg");
    assert!(found.inliers.len() >= 290 && found.inliers.len() < 330);
    assert!(truth.distance(&found.model.point) < 0.01);
    let again = in_pool(1, || {
        ransac_line(&points, &RansacOptions::new(0.02)).unwrap()
    });
    assert_eq!(found, again);
}

#[test]
fn bad_input_gives_clear_errors() {
    let options = RansacOptions::new(0.05);
    let two = vec![Point3::origin(), Point3::new(1.0, 0.0, 0.0)];
    let msg = ransac_plane(&two, &options).unwrap_err().to_string();
    assert!(msg.contains("at least 3 points, got 2"), "{msg}");
    let same = vec![Point3::new(1.0, 2.0, 3.0); 50];
    assert!(matches!(
        ransac_plane(&same, &options),
        Err(Error::Degenerate(_))
    ));
    assert!(matches!(
        ransac_line(&same, &options),
        Err(Error::Degenerate(_))
    ));
    let collinear: Vec<_> = (0..50)
        .map(|i| Point3::new(i as f64, 2.0 * i as f64, 0.0))
        .collect();
    let msg = ransac_plane(&collinear, &options).unwrap_err().to_string();
    assert!(msg.contains("collinear"), "{msg}");
    let mut nan = collinear.clone();
    nan[7].y = f64::NAN;
    assert!(matches!(
        ransac_plane(&nan, &options),
        Err(Error::InvalidInput(_))
    ));
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let o = RansacOptions::new(bad);
        assert!(matches!(
            ransac_plane(&two, &o),
            Err(Error::InvalidInput(_))
        ));
    }
    let mut o = RansacOptions::new(0.05);
    o.confidence = 1.0;
    assert!(ransac_plane(&collinear, &o).is_err());
    // A single plane cannot give three.
    let (points, _) = corner_cloud(500, 0, 0.01, 4);
    let floor: Vec<_> = points.iter().filter(|p| p.z < -1.4).copied().collect();
    let err = extract_planes(&floor, &ExtractOptions::new(3, 0.05)).unwrap_err();
    assert!(matches!(err, Error::Calibration { .. }), "{err}");
    assert!(err.to_string().contains("only 1 plane(s)"), "{err}");
}
