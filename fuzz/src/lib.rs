//! Shared body of the fuzz targets: parse the bytes with every field selection and check the
//! result's invariants. Any panic (or abort from an oversized allocation) is a bug in the parser.

use lidarcal::io::{parse_points, Fields, FileFormat};

/// Parses `data` as `format` with the default, all and a named field selection; a successful
/// parse must give a consistent table.
pub fn check(data: &[u8], format: FileFormat) {
    for fields in [
        Fields::Default,
        Fields::All,
        Fields::Named(vec!["z".into(), "intensity".into()]),
    ] {
        if let Ok(cloud) = parse_points(data, format, &fields) {
            assert_eq!(cloud.data.len(), cloud.len() * cloud.columns());
            assert!(cloud.columns() > 0);
            assert!(cloud.data.iter().all(|v| v.is_finite()));
            if cloud.columns() > 0 && cloud.len() > 0 {
                let _ = cloud.row(cloud.len() - 1);
            }
        }
    }
}
