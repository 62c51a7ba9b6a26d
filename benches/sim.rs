//! Criterion benches of the scan simulator: one revolution of a VLP-16 and of an OS1-128 in the
//! corner scene (two walls, ground, four clutter boxes), and the first two frames of the drive
//! scene (both 120-degree units, the town laid out and culled per scan).
//!
//! Run with `cargo bench --bench sim`. The point counts are printed once before timing.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use lidarcal::sim::scenes::{corner_scene, drive_scene, CornerOptions, DriveOptions};
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

fn bench_drive(c: &mut Criterion) {
    let options = DriveOptions {
        frames: 2,
        ..DriveOptions::default()
    };
    let drive = drive_scene(&options).expect("drive scene");
    eprintln!(
        "sim/drive: {} shapes, {} + {} points in the first frame",
        drive.shapes.len(),
        drive.reference_frames[0].len(),
        drive.target_frames[0].len()
    );
    c.bench_function("sim/drive two frames", |b| {
        b.iter(|| drive_scene(black_box(&options)))
    });
}

criterion_group!(benches, bench_sweeps, bench_drive);
criterion_main!(benches);
