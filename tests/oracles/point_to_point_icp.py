#!/usr/bin/env python3
"""Independent point-to-point ICP oracle (double precision, SciPy cKDTree + Kabsch SVD).

Registers ../shared/data/fast_gicp_pair (source 251371071 onto target 251370668), all points, exact
nearest neighbours within 25 cm, starting at relative.txt, iterating until a step moves less than
1e-5 cm and 1e-8 rad. Prints T_target_source (cm) as used by tests/unit/test_mapping.cpp.

relative.txt is a GICP result; point-to-point ICP has its own minimum about 1 cm and 0.36 degrees
away from it, which this oracle and minemap agree on to about 0.1 mm.
Usage: python3 -m venv v && v/bin/pip install numpy scipy && v/bin/python point_to_point_icp.py DATA_DIR
"""
import sys

import numpy as np
from scipy.spatial import cKDTree


def read_binary_pcd_cm(path):
    data = open(path, "rb").read()
    start = data.index(b"DATA binary\n") + len(b"DATA binary\n")
    header = data[:start].decode()
    count = int(next(l for l in header.splitlines() if l.startswith("POINTS")).split()[1])
    xyzi = np.frombuffer(data[start:start + count * 16], dtype=np.float32).reshape(count, 4)
    return xyzi[:, :3].astype(np.float64) * 100.0


def main(data_dir):
    target = read_binary_pcd_cm(f"{data_dir}/251370668.pcd")
    source = read_binary_pcd_cm(f"{data_dir}/251371071.pcd")
    transform = np.loadtxt(f"{data_dir}/relative.txt")
    transform[:3, 3] *= 100.0
    tree = cKDTree(target)
    for iteration in range(500):
        moved = source @ transform[:3, :3].T + transform[:3, 3]
        distance, index = tree.query(moved, distance_upper_bound=25.0)
        paired = np.isfinite(distance)
        p, q = moved[paired], target[index[paired]]
        cp, cq = p.mean(0), q.mean(0)
        u, _, vt = np.linalg.svd((p - cp).T @ (q - cq))
        d = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
        rotation = vt.T @ d @ u.T
        step = np.eye(4)
        step[:3, :3] = rotation
        step[:3, 3] = cq - rotation @ cp
        transform = step @ transform
        angle = np.arccos(min(1.0, (np.trace(rotation) - 1.0) / 2.0))
        if np.linalg.norm(step[:3, 3]) < 1e-5 and angle < 1e-8:
            break
    np.set_printoptions(precision=10, suppress=True)
    print(f"iterations {iteration + 1}, pairs {paired.sum()}")
    print(transform)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "../../../shared/data/fast_gicp_pair")
