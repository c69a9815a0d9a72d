#!/usr/bin/env python
"""Ray traversal alone: ns per ray of the scalar closest / any hit, of the packet traversal, and the
BVH's SAH node cost, on rays recorded from the scenes themselves.

    .venv/bin/python benchmarks/bench_pt_traversal.py [--scenes cornell-box mesh caustics-box] [--paths 20000]

The rays are those of a simple diffuse path tracer run on each scene (camera rays, bounce rays from
surface points, shadow rays to points on the lights), so they are as incoherent as the path
tracer's. Every kernel is warmed first; each figure is the best of ``--repeat`` runs in thread CPU
time (the machine is shared). ``--sweep`` rebuilds the BVH with other values of
``bvh_build.C_NODE`` (the cost of an interior node in units of one leaf lane): the value in the
source is the one that measured best across these scenes.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

from gdlearn.kernels.accel import bvh_build  # noqa: E402
from gdlearn.kernels.accel import packet as PT  # noqa: E402
from gdlearn.kernels.accel.bvh import STACK_SIZE, any_hit_inline, closest_hit_inline  # noqa: E402
from gdlearn.kernels.camera import camera_ray  # noqa: E402
from gdlearn.kernels.geometry import offset_origin, surface  # noqa: E402
from gdlearn.kernels.lights import sample_emitter  # noqa: E402
from gdlearn.kernels.scene_query import shadow_ray  # noqa: E402
from gdlearn.kernels.vec import coordinate_system, to_world  # noqa: E402
from gdlearn.kernels.arrays import borrowed
from gdlearn.scene.compile import compile_scene  # noqa: E402
from gdlearn.scene.load import load  # noqa: E402

RO = PT.N_S_TRACE          # the benchmark's ray set sits after the traversal's own rows


@njit(cache=True, error_model="numpy")
def record(sa, n, closest, shadows):
    """Rays of n diffuse paths (cosine bounces, roulette after 4): (closest rays, shadow rays)."""
    np.random.seed(1)
    stack = np.empty(STACK_SIZE, np.int32)
    nc = 0
    ns = 0
    for _ in range(n):
        o, d, tmax = camera_ray(sa.camera, np.random.random() * sa.camera[14], np.random.random() * sa.camera[15])
        for depth in range(8):
            closest[nc, 0:3], closest[nc, 3:6], closest[nc, 6] = o, d, tmax
            nc += 1
            t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack)
            tmax = math.inf
            if prim < 0 or depth == 7:
                break
            p, ng, _ = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
            ng = ng if d[0] * ng[0] + d[1] * ng[1] + d[2] * ng[2] < 0.0 else (-ng[0], -ng[1], -ng[2])
            em, q, nq, dl, dist, w, pdf, pa, delta = sample_emitter(
                sa.emitters, sa.em_prims, sa.em_cdf, sa.prims, sa.prim_info, p,
                np.random.random(), np.random.random(), np.random.random())
            if em >= 0:
                so, sd, st = shadow_ray(p, ng, q)
                shadows[ns, 0:3], shadows[ns, 3:6], shadows[ns, 6] = so, sd, st
                ns += 1
            r1, r2 = np.random.random(), np.random.random()
            s, tt = coordinate_system(ng)
            phi = 2.0 * math.pi * r2
            d = to_world((math.sqrt(r1) * math.cos(phi), math.sqrt(r1) * math.sin(phi), math.sqrt(1.0 - r1)), s, tt, ng)
            o = offset_origin(p, ng, d)
            if depth >= 4 and np.random.random() > 0.8:
                break
    return nc, ns


@njit(cache=True, error_model="numpy")
def _scalar(sa, rays, out, any_hit):
    stack = np.empty(STACK_SIZE, np.int32)
    for i in range(rays.shape[0]):
        o, d = (rays[i, 0], rays[i, 1], rays[i, 2]), (rays[i, 3], rays[i, 4], rays[i, 5])
        if any_hit:
            out[i] = any_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, rays[i, 6], stack,
                                    False, sa.materials)
        else:
            out[i] = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, rays[i, 6], stack)[1]


@njit(cache=True, error_model="numpy")
def _packets(sa, rays, out, any_hit):
    stack = np.empty(STACK_SIZE, np.int32)
    S = np.zeros((RO + 7) * PT.PK)
    Q = np.zeros(PT.N_Q_TRACE * PT.PK, dtype=np.int64)
    n = rays.shape[0]
    for r0 in range(0, n, PT.PK):
        m = min(PT.PK, n - r0)
        for j in range(PT.PK):
            for c in range(7):
                S[(RO + c) * PT.PK + j] = rays[r0 + min(j, m - 1), c]
            if j >= m:
                S[(RO + 6) * PT.PK + j] = -1.0
        PT.packet_trace(sa.nodes, sa.node_info, sa.prims, sa.prim_info, S, Q, RO, stack, any_hit)
        for j in range(m):
            out[r0 + j] = Q[(PT.Q_HIT if any_hit else PT.Q_PRIM) * PT.PK + j]


@njit(cache=True)
def _run_scalar(sa, rays, out, any_hit):
    _scalar(borrowed(sa), rays, out, any_hit)


@njit(cache=True)
def _run_packets(sa, rays, out, any_hit):
    _packets(borrowed(sa), rays, out, any_hit)


def best_ns(f, args, n, repeat):
    f(*args)                                                    # warm
    best = math.inf
    for _ in range(repeat):
        t0 = time.thread_time()
        f(*args)
        best = min(best, time.thread_time() - t0)
    return 1e9 * best / n


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", nargs="*", default=["cornell-box", "mesh", "caustics-box"])
    p.add_argument("--paths", type=int, default=20000)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--sweep", action="store_true", help="also time other SAH node costs")
    a = p.parse_args(argv)
    print(f"{'scene':13s} {'C_NODE':>6s} {'leaves':>6s} {'closest ns':>10s} {'any ns':>7s} {'packet closest':>14s} "
          f"{'packet any':>10s}")
    costs = [bvh_build.C_NODE] + ([4.0, 6.0, 8.0, 12.0, 24.0, 32.0] if a.sweep else [])
    for name in a.scenes:
        scene = load(ROOT / "scenes" / f"{name}.xml", res=128, max_depth=8)
        sa = compile_scene(scene)
        closest, shadows = np.zeros((8 * a.paths, 7)), np.zeros((8 * a.paths, 7))
        nc, ns = record(sa, a.paths, closest, shadows)
        closest, shadows = closest[:nc].copy(), shadows[:ns].copy()
        for c_node in costs:
            old, bvh_build.C_NODE = bvh_build.C_NODE, c_node
            try:
                sa = compile_scene(scene)
            finally:
                bvh_build.C_NODE = old
            leaves = int((sa.node_info[:, 1] > 0).sum())
            out = np.zeros(max(nc, ns), dtype=np.int64)
            row = [best_ns(_run_scalar, (sa, closest, out, False), nc, a.repeat),
                   best_ns(_run_scalar, (sa, shadows, out, True), ns, a.repeat)]
            if sa.node_info[0, 1] > 0:      # packets: one leaf
                row += [best_ns(_run_packets, (sa, closest, out, False), nc, a.repeat),
                        best_ns(_run_packets, (sa, shadows, out, True), ns, a.repeat)]
            cells = " ".join(f"{x:10.1f}" for x in row[:2]) + "".join(f"{x:15.1f}" for x in row[2:])
            print(f"{name:13s} {c_node:6.0f} {leaves:6d} {cells}")
    print("# ns per ray, best thread CPU time; packets: 64 rays at once, only where the tree is one leaf")


if __name__ == "__main__":
    main()
