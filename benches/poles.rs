//! Criterion bench of the pole method: one calibration of two VLP-16 scans of the taped-poles
//! scene (about 12k points each; the must-show asks for two ~15k-point scans in <= 20 ms), and
//! the RQE crispness of the merged cloud. Run with `cargo bench --bench poles`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use lidarcal::calib::poles::{calibrate_poles, PoleOptions, Vendor};
use lidarcal::metrics::rqe;
use lidarcal::sim::scenes::{poles_scene, PolesOptions};
use lidarcal::sim::{BeamModel, Preset, Scan};
use nalgebra::Point3;

fn split(scan: &Scan) -> (Vec<Point3<f64>>, Vec<f64>) {
    (
        scan.positions(),
        scan.points.iter().map(|p| p.intensity).collect(),
    )
}

fn bench_poles(c: &mut Criterion) {
    let model = BeamModel::preset(Preset::Vlp16);
    let scene = poles_scene(
        &model,
        &PolesOptions {
            seed: 3,
            distractor: true,
            ..PolesOptions::default()
        },
    )
    .expect("scene");
    let (r, ri) = split(&scene.reference);
    let (t, ti) = split(&scene.target);
    let mut group = c.benchmark_group("poles");
    let label = format!(
        "calibrate_poles, VLP-16 scans of {} and {} points",
        r.len(),
        t.len()
    );
    for (name, options) in [
        (
            "vendor threshold",
            PoleOptions {
                vendor: Some(Vendor::Velodyne),
                ..PoleOptions::default()
            },
        ),
        ("data threshold", PoleOptions::default()),
    ] {
        group.bench_function(format!("{label}, {name}"), |b| {
            b.iter(|| calibrate_poles(black_box(&r), &ri, black_box(&t), &ti, &options))
        });
    }
    let merged: Vec<Point3<f64>> = r
        .iter()
        .copied()
        .chain(t.iter().map(|p| scene.reference_from_target * p))
        .collect();
    group.bench_function(format!("rqe, sigma 0.05, {} points", merged.len()), |b| {
        b.iter(|| rqe(black_box(&merged), 0.05))
    });
    group.finish();
}

criterion_group!(benches, bench_poles);
criterion_main!(benches);
