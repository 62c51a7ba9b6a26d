//! Every input that once crashed, hung or exhausted memory in a parser (found by the fuzzers in
//! `fuzz/`) is kept in `fuzz/regressions/<format>/` and must now parse to a clean `Err` (or `Ok`)
//! without panicking, quickly and without a large allocation.

#![cfg(feature = "io")]

use std::path::Path;
use std::time::{Duration, Instant};

use lidarcal::io::{parse_points, Fields, FileFormat};

fn format_of(dir: &str) -> Option<FileFormat> {
    Some(match dir {
        "pcd" => FileFormat::Pcd,
        "ply" => FileFormat::Ply,
        "npy" => FileFormat::Npy,
        "text" => FileFormat::Text,
        "kitti" => FileFormat::Kitti,
        _ => return None,
    })
}

#[test]
fn fuzz_regressions_parse_without_panicking() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/regressions");
    let mut checked = 0;
    for dir in std::fs::read_dir(&root).expect("fuzz/regressions exists") {
        let dir = dir.expect("readable directory entry").path();
        let name = dir.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        let Some(format) = format_of(name) else {
            continue;
        };
        for file in std::fs::read_dir(&dir).expect("readable format directory") {
            let file = file.expect("readable file entry").path();
            let bytes = std::fs::read(&file).expect("readable regression input");
            for fields in [Fields::Default, Fields::All] {
                let start = Instant::now();
                let result = parse_points(&bytes, format, &fields);
                assert!(
                    start.elapsed() < Duration::from_secs(5),
                    "{}: parsing took {:?}",
                    file.display(),
                    start.elapsed()
                );
                if let Ok(cloud) = result {
                    assert_eq!(cloud.data.len(), cloud.len() * cloud.columns());
                }
            }
            checked += 1;
        }
    }
    assert!(
        checked > 0,
        "no regression inputs found under {}",
        root.display()
    );
}

#[test]
fn absurd_pcd_count_is_refused_before_allocating() {
    let header =
        b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 2222222222222222221\n\
WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA binary\n";
    let err = parse_points(header, FileFormat::Pcd, &Fields::Default).unwrap_err();
    assert!(err.to_string().contains("values per point"), "{err}");
}
