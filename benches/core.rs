//! Criterion benches of the numerical kernels: Kabsch (3 normals, as the corner method uses it,
//! and 10 000 vectors) and one Levenberg–Marquardt solve of a three-plane, 10 000-point alignment.
//!
//! Run with `cargo bench --bench core`. The LM iteration count of the benched problem is printed
//! once before timing.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use lidarcal::kabsch::kabsch;
use lidarcal::lm::{solve, LmOptions, Loss};
use lidarcal::residuals::PointToPlane;
use nalgebra::{Rotation3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[path = "../tests/common/mod.rs"]
mod common;

fn bench_kabsch(c: &mut Criterion) {
    let r_true = Rotation3::from_euler_angles(0.3, -0.2, 1.4);
    let normals = [
        Vector3::new(-1.0, 0.15, 0.0).normalize(),
        Vector3::new(0.1, -1.0, 0.05).normalize(),
        Vector3::new(0.0, 0.05, 1.0).normalize(),
    ];
    let rotated: Vec<_> = normals.iter().map(|n| r_true * n).collect();
    c.bench_function("kabsch/3 normals", |b| {
        b.iter(|| kabsch(black_box(&rotated), black_box(&normals), None))
    });

    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let many: Vec<Vector3<f64>> = (0..10_000)
        .map(|_| {
            Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        })
        .collect();
    let many_rotated: Vec<_> = many.iter().map(|v| r_true * v).collect();
    c.bench_function("kabsch/10k vectors", |b| {
        b.iter(|| kabsch(black_box(&many_rotated), black_box(&many), None))
    });
}

fn bench_lm(c: &mut Criterion) {
    // 3 planes x 3334 points = 10 002 points, 2 cm noise, start 5.7 deg / 0.35 m off.
    let problem = PointToPlane::new(common::corner_groups(3334, 0.02, 1), Loss::Squared)
        .expect("valid problem");
    let start = common::perturbed_start();
    let options = LmOptions::default();
    let solution = solve(&problem, &start, &options).expect("solve");
    eprintln!(
        "lm/3 planes 10k points: {} iterations, {} evaluations, termination {}, cost {:.3e} -> {:.3e}",
        solution.report.iterations,
        solution.report.evaluations,
        solution.report.termination.as_str(),
        solution.report.initial_cost,
        solution.report.final_cost
    );
    c.bench_function("lm/3 planes 10k points", |b| {
        b.iter(|| solve(black_box(&problem), black_box(&start), &options))
    });
}

criterion_group!(benches, bench_kabsch, bench_lm);
criterion_main!(benches);
