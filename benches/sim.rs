//! Criterion benches of the scan simulator: one revolution of a VLP-16 and of an OS1-128 in the
//! corner scene (two walls, ground, four clutter boxes).
//!
//! Run with `cargo bench --bench sim`. The point counts are printed once before timing.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use lidarcal::sim::scenes::{corner_scene, CornerOptions};
use lidarcal::sim::{scan, BeamModel, Preset, ScanOptions};

fn bench_sweeps(c: &mut Criterion) {
    let vlp16 = BeamModel::preset(Preset::Vlp16);
    let scene = corner_scene(&vlp16, &CornerOptions::default()).expect("corner scene");
    let options = ScanOptions::default();
    for preset in [Preset::Vlp16, Preset::Os1_128] {
        let model = BeamModel::preset(preset);
        let points = scan(&model, &scene.shapes, &scene.world_from_reference, &options)
            .expect("scan")
            .len();
        eprintln!(
            "sim/{} sweep: {} shapes, {} rays, {points} points",
            preset.name(),
            scene.shapes.len(),
            model.beams() * model.columns()
        );
        c.bench_function(&format!("sim/{} corner sweep", preset.name()), |b| {
            b.iter(|| {
                scan(
                    black_box(&model),
                    black_box(&scene.shapes),
                    &scene.world_from_reference,
                    &options,
                )
            })
        });
    }
}

criterion_group!(benches, bench_sweeps);
criterion_main!(benches);
