"""Import Open3D where the system lacks the libusb-1.0 its wheel links against.

Open3D's Linux wheels link ``libusb-1.0.so.0`` (for the RealSense driver they bundle), which a
minimal machine does not have: ``import open3d`` then fails with ``ImportError:
libusb-1.0.so.0: cannot open shared object file``. The ``bench`` extra installs
``libusb-package``, which ships that library inside a Python package; loading it with
``RTLD_GLOBAL`` before the import satisfies the link without touching the system. Where the
system has libusb, the plain import works and the package is not used.
"""

from __future__ import annotations

import ctypes
from types import ModuleType


def import_open3d() -> ModuleType:
    """``import open3d``, preloading ``libusb_package``'s libusb-1.0 when the system has none.

    Raises ImportError, with what to install, when Open3D cannot be imported.
    """
    try:
        import open3d

        return open3d
    except ImportError as first:
        if "libusb" not in str(first):
            raise ImportError(f"Open3D is needed: pip install -e '.[bench]' ({first})") from first
        try:
            import libusb_package
        except ImportError:
            raise ImportError(
                "Open3D needs libusb-1.0: pip install libusb-package (in the bench extra), "
                f"or the system's package (Debian: apt install libusb-1.0-0); {first}"
            ) from first
        path = libusb_package.get_library_path()
        if path is None:
            raise ImportError(
                f"libusb-package has no library for this platform; {first}"
            ) from first
        ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
        import open3d

        return open3d
