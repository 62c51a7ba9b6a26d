//! Criterion bench of calibration from a drive (issue 19): the odometry of one unit over 50
//! frames, and `calibrate_sequence` on a whole 20 s simulated drive (200 frame pairs of about
//! 37k + 36k points: both units' odometry side by side, hand-eye, the map alignment).
//! Run with `cargo bench --bench sequence` (the drive takes about 10 s to simulate first, and
//! each calibration about 5 s, so the samples are few).

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use lidarcal::calib::sequence::{calibrate_sequence, SequenceOptions};
use lidarcal::odometry::{odometry, OdometryOptions};
use lidarcal::sim::scenes::{drive_scene, DriveOptions};

fn bench_sequence(c: &mut Criterion) {
    let drive = drive_scene(&DriveOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let reference: Vec<_> = drive
        .reference_frames
        .iter()
        .map(|s| s.positions())
        .collect();
    let target: Vec<_> = drive.target_frames.iter().map(|s| s.positions()).collect();
    let mut group = c.benchmark_group("sequence");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(60));
    group.bench_function("odometry, 50 frames of ~37k points", |b| {
        b.iter(|| odometry(black_box(&reference[..50]), &OdometryOptions::default()))
    });
    let options = SequenceOptions::default();
    match calibrate_sequence(&reference, &target, &options) {
        Ok(result) => println!("stages (ms): {:?}", result.timings.stages),
        Err(e) => panic!("the default drive did not calibrate: {e}"),
    }
    group.bench_function("calibrate_sequence, 200 frame pairs", |b| {
        b.iter(|| calibrate_sequence(black_box(&reference), black_box(&target), &options))
    });
    group.finish();
}

criterion_group!(benches, bench_sequence);
criterion_main!(benches);
