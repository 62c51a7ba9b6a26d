"""Writes the seed corpus of the fuzz targets: small valid files of every variant the readers know.

Run from anywhere: ``python fuzz/make_corpus.py`` (standard library only). The output is
committed under ``fuzz/corpus/<target>/``; libFuzzer adds what it finds next to it when run
with that directory (keep those out of git: ``fuzz/.gitignore``).
"""

from __future__ import annotations

import struct
from pathlib import Path

ROOT = Path(__file__).resolve().parent / "corpus"
XYZI = [(1.0, 2.0, 3.0, 10.0), (4.5, -5.0, 6.25, 200.0), (-7.0, 8.0, 0.0, 255.0)]


def lzf_literal(raw: bytes) -> bytes:
    """Valid LZF made of literal runs only (at most 32 bytes each)."""
    out = bytearray()
    for i in range(0, len(raw), 32):
        chunk = raw[i : i + 32]
        out.append(len(chunk) - 1)
        out += chunk
    return bytes(out)


def pcd_header(fields: str, size: str, typ: str, count: str, n: int, kind: str) -> bytes:
    return (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {fields}\nSIZE {size}\nTYPE {typ}\nCOUNT {count}\n"
        f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {kind}\n"
    ).encode()


def pcd_seeds() -> dict[str, bytes]:
    n = len(XYZI)
    seeds = {}
    body = "".join(f"{x} {y} {z} {i}\n" for x, y, z, i in XYZI)
    seeds["ascii_xyzi.pcd"] = (
        pcd_header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", n, "ascii") + body.encode()
    )
    body = "".join(f"{x} {y} {z} nan 7 8\n" for x, y, z, _ in XYZI)
    seeds["ascii_count.pcd"] = (
        pcd_header("x y z n", "4 4 4 4", "F F F F", "1 1 1 3", n, "ascii") + body.encode()
    )
    rec = b"".join(struct.pack("<4f", *p) for p in XYZI)
    seeds["binary_xyzi.pcd"] = (
        pcd_header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", n, "binary") + rec
    )
    rec = b"".join(struct.pack("<dddBxxxI", x, y, z, int(i), 7) for x, y, z, i in XYZI)
    seeds["binary_mixed_pad.pcd"] = (
        pcd_header(
            "x y z reflectivity _ ring", "8 8 8 1 1 4", "F F F U U U", "1 1 1 1 3 1", n, "binary"
        )
        + rec
    )
    cols = b"".join(struct.pack(f"<{n}f", *[p[c] for p in XYZI]) for c in range(4))
    seeds["compressed_xyzi.pcd"] = (
        pcd_header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", n, "binary_compressed")
        + struct.pack("<II", len(lzf_literal(cols)), len(cols))
        + lzf_literal(cols)
    )
    seeds["empty.pcd"] = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 0, "binary")
    return seeds


def ply_seeds() -> dict[str, bytes]:
    n = len(XYZI)
    head = (
        "ply\nformat {fmt} 1.0\ncomment made by make_corpus.py\nelement vertex {n}\n"
        "property float x\nproperty float y\nproperty float z\nproperty uchar intensity\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    )
    seeds = {}
    body = "".join(f"{x} {y} {z} {int(i)}\n" for x, y, z, i in XYZI) + "3 0 1 2\n"
    seeds["ascii.ply"] = head.format(fmt="ascii", n=n).encode() + body.encode()
    for fmt, e in (("binary_little_endian", "<"), ("binary_big_endian", ">")):
        body_b = b"".join(struct.pack(f"{e}fffB", x, y, z, int(i)) for x, y, z, i in XYZI)
        body_b += struct.pack(f"{e}Biii", 3, 0, 1, 2)
        seeds[f"{fmt}.ply"] = head.format(fmt=fmt, n=n).encode() + body_b
    head2 = (
        "ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty double x\n"
        "property double y\nproperty double z\nproperty list uchar float normals\n"
        "property ushort scalar_intensity\nend_header\n"
    )
    body_b = struct.pack("<dddB2fH", 1, 2, 3, 2, 0.5, 0.5, 9) + struct.pack(
        "<dddB1fH", 4, 5, 6, 1, 0.1, 3
    )
    seeds["vertex_list.ply"] = head2.encode() + body_b
    return seeds


def npy_seeds() -> dict[str, bytes]:
    def npy(
        descr: str, shape: tuple[int, int], data: bytes, fortran: bool = False, v2: bool = False
    ) -> bytes:
        header = f"{{'descr': '{descr}', 'fortran_order': {fortran}, 'shape': {shape}, }}"
        prefix = 12 if v2 else 10
        header += " " * ((64 - (prefix + len(header) + 1) % 64) % 64) + "\n"
        if v2:
            return b"\x93NUMPY\x02\x00" + struct.pack("<I", len(header)) + header.encode() + data
        return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + data

    flat = [v for p in XYZI for v in p]
    return {
        "f8.npy": npy("<f8", (3, 4), struct.pack("<12d", *flat)),
        "f4_big.npy": npy(">f4", (3, 4), struct.pack(">12f", *flat)),
        "i4_fortran.npy": npy(
            "<i4", (3, 4), struct.pack("<12i", *[int(v) for v in flat]), fortran=True
        ),
        "u1_v2.npy": npy("|u1", (4, 3), bytes(range(12)), v2=True),
    }


def text_seeds() -> dict[str, bytes]:
    return {
        "header.csv": b"x,y,z,intensity\n1,2,3,4\n5,6,7,8\n# comment\n9,10,11,12\n",
        "plain.txt": b"1 2 3\n4.5 -5e-3 6\n\n7 8 nan\n",
        "semicolon.xyz": b"X;Y;Z;reflectance\n1;2;3;0.5\n4;5;6;0.25\n",
    }


def main() -> None:
    for target, seeds in (
        ("pcd", pcd_seeds()),
        ("ply", ply_seeds()),
        ("npy", npy_seeds()),
        ("text", text_seeds()),
    ):
        d = ROOT / target
        d.mkdir(parents=True, exist_ok=True)
        for name, data in seeds.items():
            (d / name).write_bytes(data)
        print(f"{target}: {len(seeds)} seeds in {d}")


if __name__ == "__main__":
    main()
