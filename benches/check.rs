//! Criterion bench of `lidarcal::check`: one certification of a calibrated pair, as a rig
//! monitor would run it. The largest real pair (the hesai P64 against qt_204, ~106k + ~25k
//! points) at the targetless method's own result when ../shared is present, and a simulated
//! street pair (120k + 27k points) and the paper scene of the corner method (9.5k + 9.5k) at
//! their ground truth.
//! Run with `cargo bench --bench check`.

#[path = "../tests/common/mod.rs"]
mod common;

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use lidarcal::calib::targetless::{calibrate_targetless, TargetlessOptions};
use lidarcal::check::{check, CheckOptions};
use lidarcal::sim::scenes::{paper_scene, street_scene, PaperOptions, StreetOptions};

fn bench_check(c: &mut Criterion) {
    let options = CheckOptions::default();
    if let Some(dir) = common::sensors_calibration_dir() {
        let hesai = dir.join("hesai_scene1");
        let p64 = common::load_npy_xyz(&hesai.join("p64.npy"));
        let qt = common::load_npy_xyz(&hesai.join("qt_204.npy"));
        match calibrate_targetless(&p64, &qt, &TargetlessOptions::default()) {
            Ok(result) => {
                let pose = result.reference_from_target;
                println!("hesai qt_204->p64: {}", result.check);
                c.bench_function("check hesai qt_204->p64 (106k + 25k points)", |b| {
                    b.iter(|| check(black_box(&p64), black_box(&qt), &pose, &options))
                });
            }
            Err(e) => println!("hesai qt_204->p64 not calibrated: {e}"),
        }
    }
    let scene = street_scene(&StreetOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let (reference, target) = (scene.reference.positions(), scene.target.positions());
    let truth = scene.reference_from_target;
    c.bench_function("check simulated street (120k + 27k points)", |b| {
        b.iter(|| check(black_box(&reference), black_box(&target), &truth, &options))
    });
    // A small pair: what a check costs whatever the clouds' size (the corner method certifies
    // every result of the paper's protocol this way).
    let paper = PaperOptions {
        alpha_deg: 100.0,
        ..PaperOptions::default()
    };
    let scene = paper_scene(&paper).unwrap_or_else(|e| panic!("{e}"));
    let (reference, target) = (scene.reference.positions(), scene.target.positions());
    let truth = scene.reference_from_target;
    c.bench_function("check paper scene (9.5k + 9.5k points)", |b| {
        b.iter(|| check(black_box(&reference), black_box(&target), &truth, &options))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench_check
}
criterion_main!(benches);
