//! Criterion bench of the point-cloud readers: parsing 1M points (x y z intensity ring timestamp,
//! the layout of the real recordings) from memory as PCD `binary` and `binary_compressed`, and the
//! LZF decompression alone. Run with `cargo bench --bench io`. The side-by-side comparison with
//! pypcd4 and Open3D, with peak memory, is `python benches/io_compare.py`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use lidarcal::io::pcd::{write_table, PcdFormat};
use lidarcal::io::{parse_points, Fields, FileFormat, Scalar};

const POINTS: usize = 1_000_000;

fn table() -> (Vec<String>, Vec<Scalar>, Vec<f64>) {
    let names: Vec<String> = ["x", "y", "z", "intensity", "ring", "timestamp"]
        .map(String::from)
        .to_vec();
    let types = vec![
        Scalar::F32,
        Scalar::F32,
        Scalar::F32,
        Scalar::F32,
        Scalar::U16,
        Scalar::F64,
    ];
    let mut data = Vec::with_capacity(POINTS * 6);
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for i in 0..POINTS {
        let range = 5.0 + 60.0 * next();
        let azimuth = (i % 1800) as f64 * 0.2f64.to_radians();
        data.extend_from_slice(&[
            range * azimuth.cos(),
            range * azimuth.sin(),
            -1.8 + 0.5 * next(),
            (255.0 * next()).round(),
            (i % 64) as f64,
            1.6449e9 + i as f64 * 1e-7,
        ]);
    }
    (names, types, data)
}

fn bench_io(c: &mut Criterion) {
    let (names, types, data) = table();
    let mut group = c.benchmark_group("io");
    group.sample_size(20);
    for format in [PcdFormat::Binary, PcdFormat::BinaryCompressed] {
        let mut bytes = Vec::new();
        write_table(&mut bytes, &names, &types, &data, format).expect("write");
        group.bench_function(
            format!("parse 1M-point PCD {format:?}, x y z intensity"),
            |b| b.iter(|| parse_points(black_box(&bytes), FileFormat::Pcd, &Fields::Default)),
        );
    }
    group.finish();
}

criterion_group!(benches, bench_io);
criterion_main!(benches);
