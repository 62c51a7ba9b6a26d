//! Criterion bench of the targetless method: one calibration of a real road pair (the 64-beam
//! roof unit against a 45-degree-tilted side unit, ~90k and ~9k points) when ../shared is
//! present, the largest hesai pair (P64 against qt_204, ~106k and ~25k points), and a simulated
//! street pair. The per-stage breakdown of one run is printed first.
//! Run with `cargo bench --bench targetless`.

#[path = "../tests/common/mod.rs"]
mod common;

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use lidarcal::calib::targetless::{calibrate_targetless, TargetlessOptions};
use lidarcal::sim::scenes::{street_scene, StreetOptions};
use nalgebra::Point3;

fn stages(name: &str, reference: &[Point3<f64>], target: &[Point3<f64>]) {
    match calibrate_targetless(reference, target, &TargetlessOptions::default()) {
        Ok(r) => {
            let parts: Vec<String> = r
                .timings
                .stages
                .iter()
                .map(|(s, ms)| format!("{s} {ms:.1} ms"))
                .collect();
            println!(
                "{name}: {} (total {:.1} ms)",
                parts.join(", "),
                r.timings.total()
            );
        }
        Err(e) => println!("{name}: {e}"),
    }
}

fn bench_targetless(c: &mut Criterion) {
    let options = TargetlessOptions::default();
    if let Some(dir) = common::sensors_calibration_dir() {
        let base = dir.join("real_world").join(common::REAL_WORLD_SCENES[1]);
        let top = common::load_npy_xyz(&base.join("top.npy"));
        let left = common::load_npy_xyz(&base.join("left.npy"));
        stages("real left->top", &top, &left);
        c.bench_function("targetless real left->top (92k + 9k points)", |b| {
            b.iter(|| calibrate_targetless(black_box(&top), black_box(&left), &options))
        });
        let hesai = dir.join("hesai_scene1");
        let p64 = common::load_npy_xyz(&hesai.join("p64.npy"));
        let qt = common::load_npy_xyz(&hesai.join("qt_204.npy"));
        stages("hesai qt_204->p64", &p64, &qt);
        c.bench_function("targetless hesai qt_204->p64 (106k + 25k points)", |b| {
            b.iter(|| calibrate_targetless(black_box(&p64), black_box(&qt), &options))
        });
    }
    let scene = street_scene(&StreetOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let (reference, target) = (scene.reference.positions(), scene.target.positions());
    stages("simulated street", &reference, &target);
    c.bench_function("targetless simulated street (120k + 27k points)", |b| {
        b.iter(|| calibrate_targetless(black_box(&reference), black_box(&target), &options))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench_targetless
}
criterion_main!(benches);
