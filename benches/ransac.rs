//! Criterion benches of RANSAC: the scoring kernel alone (throughput in point-tests per second on
//! one core), single-plane RANSAC, and three-plane extraction on 10k and 100k-point corner clouds
//! with 20 % clutter. Run with `cargo bench --bench ransac`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use lidarcal::ransac::consensus::{Score, GROUP};
use lidarcal::ransac::plane::{extract_planes, ransac_plane, score_planes_f32, ExtractOptions};
use lidarcal::ransac::{Cloud, RansacOptions};
use nalgebra::Vector3;

#[path = "../tests/common/mod.rs"]
mod common;

fn bench_kernel(c: &mut Criterion) {
    let (points, _) = common::corner_cloud(250_000, 250_000, 0.03, 1); // 1M points
    let cloud = Cloud::new(&points).expect("finite");
    let (x, y, z) = cloud.soa();
    let planes: Vec<[f32; 4]> = (0..GROUP)
        .map(|k| {
            let n = Vector3::new(1.0, 0.1 * k as f64, 0.3).normalize();
            [n.x as f32, n.y as f32, n.z as f32, -0.5]
        })
        .collect();
    let mut group = c.benchmark_group("ransac/kernel");
    group.throughput(Throughput::Elements((x.len() * GROUP) as u64));
    for (label, count) in [("cost only", false), ("cost and inlier count", true)] {
        group.bench_function(format!("8 planes x 1M points, 1 thread, {label}"), |b| {
            let mut out = [Score::default(); GROUP];
            b.iter(|| {
                score_planes_f32(
                    count,
                    black_box(x),
                    black_box(y),
                    black_box(z),
                    &planes,
                    0.05,
                    &mut out,
                )
            })
        });
    }
    group.finish();
}

fn bench_ransac(c: &mut Criterion) {
    for &total in &[10_000usize, 100_000] {
        let per_plane = total * 8 / 30; // 80 % on three planes, 20 % clutter
        let (points, _) = common::corner_cloud(per_plane, total - 3 * per_plane, 0.03, 2);
        let options = ExtractOptions::new(3, 0.09);
        let found = extract_planes(&points, &options).expect("three planes");
        let hypotheses: usize = found.iter().map(|p| p.hypotheses).sum();
        eprintln!("extract_planes {total}: {hypotheses} hypotheses in total");
        c.bench_function(&format!("ransac/extract 3 planes {}k", total / 1000), |b| {
            b.iter(|| extract_planes(black_box(&points), &options))
        });
        c.bench_function(&format!("ransac/plane {}k", total / 1000), |b| {
            b.iter(|| ransac_plane(black_box(&points), &RansacOptions::new(0.09)))
        });
    }
}

criterion_group!(benches, bench_kernel, bench_ransac);
criterion_main!(benches);
