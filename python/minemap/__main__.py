"""`minemap` from the Python package (`python -m minemap`, or the `minemap` command pip installs):
the C++ command line itself (simulate, map), with LAS/LAZ and E57 surveys read and map.laz written
by this package, and `minemap batch`, which maps many surveys on a Dask cluster."""
from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["batch"]:
        from .batch import main as batch_main
        return batch_main(argv[1:])
    from . import _core
    code = _core.run_cli(argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("\nFrom the Python package also:\n  batch                       Map many surveys on a Dask cluster "
              "(minemap batch --help)")
    return code


def console() -> None:
    sys.exit(main())


if __name__ == "__main__":
    console()
