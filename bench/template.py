"""Benchmark: template generation time and sizes at the default and 10x resolution.

Usage: python bench/template.py [resolution ...]   (default: 1 10)
"""
import resource
import sys
import time

import invface


def main(resolutions):
    print(f"{'resolution':>10s} {'seconds':>8s} {'surf verts':>10s} {'tet verts':>9s} {'tets':>8s} "
          f"{'min dih':>7s} {'min rr':>6s} {'muscles':>7s} {'peak RSS':>9s}")
    for r in resolutions:
        t0 = time.perf_counter()
        m = invface.template.generate(resolution=r)
        dt = time.perf_counter() - t0
        s = m.summary()
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"{r:10g} {dt:8.1f} {s['surface_vertices']:10d} {s['vertices']:9d} {s['tets']:8d} "
              f"{s['min_dihedral_deg']:7.2f} {s['min_radius_ratio']:6.3f} {s['muscles']:7d} {rss:7.0f}MB", flush=True)


if __name__ == "__main__":
    main([float(a) for a in sys.argv[1:]] or [1.0, 10.0])
