"""File formats: exact reading of the real recordings, round trips, and malformed files."""

import struct
from pathlib import Path

import numpy as np
import pytest

import lidarcal
from eval_data import require

POINTS = np.array(
    [[0.5, -1.25, 3.0, 10.0], [1.0, 2.0, -3.5, 0.0], [100.25, 0.0, 1e-3, 255.0]], dtype=np.float64
)


def test_every_real_pcd_matches_its_npy_copy() -> None:
    root = require("SensorsCalibration")
    pairs = []
    for pcd in sorted(root.rglob("*.pcd")):
        npy = pcd.with_name(pcd.name.split("-")[0].removesuffix(".pcd") + ".npy")
        if npy.exists():
            pairs.append((pcd, npy))
    assert len(pairs) == 14  # 5 hesai units + 3 scenes x 3 units
    for pcd, npy in pairs:
        expected = np.load(npy).astype(np.float64)
        got, info = lidarcal.read_points(pcd, "all", with_info=True)
        assert got.dtype == np.float64
        assert info["dropped_non_finite"] == 0
        assert info["points"] == len(expected)
        # The .npy copies hold the first columns (x y z intensity [ring]) of the PCD.
        np.testing.assert_array_equal(got[:, : expected.shape[1]], expected, err_msg=str(pcd))


def test_padding_fields_and_ply_intensity_aliases() -> None:
    corner = require("lidar_appearance_calibration")
    ref = lidarcal.read_points(corner / "ref_filter.pcd")  # FIELDS x y z _ (COUNT 4 padding)
    np.testing.assert_array_equal(ref, np.load(corner / "ref_filter.npy").astype(np.float64))
    gicp = require("small_gicp")
    cloud, info = lidarcal.read_points(gicp / "source.ply", with_info=True)
    assert info["available"] == ["x", "y", "z", "scalar_intensity"]
    assert info["fields"] == ["x", "y", "z", "intensity"]
    np.testing.assert_array_equal(cloud, np.load(gicp / "source.npy").astype(np.float64))


@pytest.mark.parametrize("ext", ["pcd", "ply", "bin", "npy", "csv", "txt"])
def test_round_trip(tmp_path: Path, ext: str) -> None:
    path = tmp_path / f"cloud.{ext}"
    lidarcal.write_points(path, POINTS)
    got = lidarcal.read_points(path)
    # PCD, PLY and KITTI store float32; the others are exact.
    expected = POINTS.astype(np.float32) if ext in ("pcd", "ply", "bin") else POINTS
    np.testing.assert_array_equal(got, expected.astype(np.float64))


@pytest.mark.parametrize("encoding", ["binary", "binary_compressed", "ascii"])
def test_pcd_encodings_round_trip(tmp_path: Path, encoding: str) -> None:
    path = tmp_path / "cloud.pcd"
    big = np.random.default_rng(0).normal(size=(5000, 4)) * 20
    lidarcal.write_points(path, big, pcd_format=encoding)  # type: ignore[arg-type]
    assert f"DATA {encoding}\n".encode() in path.read_bytes()[:400]
    np.testing.assert_array_equal(lidarcal.read_points(path), big.astype(np.float32))
    with pytest.raises(ValueError, match="pcd_format must be"):
        lidarcal.write_points(path, big, pcd_format="zip")  # type: ignore[arg-type]


def test_fields_selection_and_names(tmp_path: Path) -> None:
    path = tmp_path / "c.csv"
    data = np.column_stack([POINTS, [7, 8, 9]])
    lidarcal.write_points(path, data, fields=["x", "y", "z", "reflectivity", "ring"])
    assert path.read_text().splitlines()[0] == "x,y,z,reflectivity,ring"
    np.testing.assert_array_equal(lidarcal.read_points(path, ["ring", "x"]), data[:, [4, 0]])
    np.testing.assert_array_equal(lidarcal.read_points(path, "all"), data)
    np.testing.assert_array_equal(lidarcal.read_points(path), data[:, :4])
    with pytest.raises(ValueError, match='no field "timestamp"'):
        lidarcal.read_points(path, ["timestamp"])
    with pytest.raises(ValueError, match='fields must be None, "all"'):
        lidarcal.read_points(path, "everything")


def test_npy_reader_matches_numpy(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    for dtype in ("<f4", ">f8", "<i2", "u1"):
        a = (rng.random((50, 5)) * 100).astype(dtype)
        for order in ("C", "F"):
            path = tmp_path / f"a_{dtype.strip('<>')}_{order}.npy"
            np.save(path, np.asarray(a, order=order))
            np.testing.assert_array_equal(lidarcal.read_points(path, "all"), a.astype(np.float64))


def test_non_finite_points_are_dropped_and_counted(tmp_path: Path) -> None:
    path = tmp_path / "nan.npy"
    a = POINTS.copy()
    a[1, 2] = np.nan
    a[2, 3] = np.inf
    np.save(path, a)
    got, info = lidarcal.read_points(path, with_info=True)
    np.testing.assert_array_equal(got, a[:1])
    assert info["dropped_non_finite"] == 2
    # Only the selected columns count: without intensity the inf row stays.
    got = lidarcal.read_points(path, ["x", "y", "z"])
    assert len(got) == 2


def _pcd(header_fields: str, data: bytes, points: int = 2, kind: str = "binary") -> bytes:
    names = header_fields.split()
    head = (
        f"VERSION .7\nFIELDS {header_fields}\nSIZE {' '.join('4' for _ in names)}\n"
        f"TYPE {' '.join('F' for _ in names)}\nCOUNT {' '.join('1' for _ in names)}\n"
        f"WIDTH {points}\nHEIGHT 1\nPOINTS {points}\nDATA {kind}\n"
    )
    return head.encode() + data


FFE = lidarcal.FileFormatError
GOOD_XYZ = struct.pack("<6f", 1, 2, 3, 4, 5, 6)

# (name, file name, bytes, exception, message fragment). The message always names the file too.
MALFORMED = [
    ("empty file", "a.pcd", b"", FFE, "before its DATA line"),
    ("garbage", "a.pcd", b"\x00\xff" * 100, FFE, "not a PCD"),
    ("text but not PCD", "a.pcd", b"hello\nworld\n", FFE, "unknown header"),
    ("truncated binary", "a.pcd", _pcd("x y z", GOOD_XYZ[:-5]), FFE, "truncated"),
    ("no DATA line", "a.pcd", _pcd("x y z", b"")[:-12], FFE, "DATA line"),
    ("unknown DATA kind", "a.pcd", _pcd("x y z", b"", kind="zip"), FFE, 'DATA "zip"'),
    ("no x field", "a.pcd", _pcd("a b c", GOOD_XYZ), FFE, "no field 'x'"),
    (
        "bad LZF block",
        "a.pcd",
        _pcd("x y z", struct.pack("<II", 3, 24) + b"\xe0\xff\xff", kind="binary_compressed"),
        FFE,
        "corrupt LZF",
    ),
    (
        "LZF size mismatch",
        "a.pcd",
        _pcd("x y z", struct.pack("<II", 3, 99) + b"\x00\x00\x00", kind="binary_compressed"),
        FFE,
        "need 24",
    ),
    (
        "ascii non-number",
        "a.pcd",
        _pcd("x y z", b"1 2 3\n4 five 6\n", kind="ascii"),
        FFE,
        '"five" is not a number',
    ),
    ("PLY without magic", "a.ply", b"PLY\n", FFE, "not a PLY"),
    (
        "PLY truncated header",
        "a.ply",
        b"ply\nformat ascii 1.0\nelement vertex 2\n",
        FFE,
        "end_header",
    ),
    (
        "PLY truncated body",
        "a.ply",
        b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\n"
        b"property float y\nproperty float z\nend_header\n" + GOOD_XYZ[:20],
        FFE,
        "truncated",
    ),
    ("KITTI odd size", "a.bin", b"\x00" * 30, FFE, "16-byte records"),
    ("npy without magic", "a.npy", b"PK\x03\x04", FFE, "not a .npy"),
    ("CSV ragged row", "a.csv", b"1,2,3\n4,5\n", FFE, "line 2"),
    ("CSV empty", "a.csv", b"# only a comment\n", FFE, "no data lines"),
    ("unknown extension", "a.las", b"LASF", ValueError, "unknown point-cloud extension"),
]


@pytest.mark.parametrize(
    ("name", "filename", "content", "exc", "fragment"), MALFORMED, ids=[m[0] for m in MALFORMED]
)
def test_malformed_files_raise_clear_errors(
    tmp_path: Path, name: str, filename: str, content: bytes, exc: type, fragment: str
) -> None:
    path = tmp_path / filename
    path.write_bytes(content)
    with pytest.raises(exc, match=None) as info:
        lidarcal.read_points(path)
    message = str(info.value)
    assert fragment in message, message
    assert str(path) in message, message


def test_os_errors_map_to_their_subclasses(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"missing\.pcd"):
        lidarcal.read_points(tmp_path / "missing.pcd")
    (tmp_path / "dir.pcd").mkdir()
    with pytest.raises(IsADirectoryError, match=r"dir\.pcd"):
        lidarcal.read_points(tmp_path / "dir.pcd")
    with pytest.raises(FileNotFoundError):
        lidarcal.write_points(tmp_path / "no" / "such" / "dir.pcd", POINTS)


def test_write_rejects_bad_arrays(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="2-D array"):
        lidarcal.write_points(tmp_path / "a.pcd", np.zeros(6))
    with pytest.raises(ValueError, match="non-finite"):
        lidarcal.write_points(tmp_path / "a.pcd", np.full((2, 3), np.nan))
    with pytest.raises(ValueError, match="fields names 2"):
        lidarcal.write_points(tmp_path / "a.pcd", POINTS, fields=["x", "y"])
    with pytest.raises(ValueError, match="plain word"):
        lidarcal.write_points(tmp_path / "a.pcd", POINTS, fields=["x", "y", "z", "in tensity"])
