"""Ray-casting benchmark: 640x480 depth frames per second in the office world.

Renders the frames a robot sees along its route with the tiled packet caster that
`DepthCamera` uses, and the same pixels through the per-ray BVH traversal (the LiDAR path) as
the in-run baseline; on one core (RAYON_NUM_THREADS=1, the issue's figure) and on all cores.
Also times the whole sensor model (noise and quantisation included). Prints one JSON object.

    .venv/bin/python benchmarks/raycast.py [--frames 40]
"""

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np


def measure(frames: int) -> dict:
    from gmmap.io.sim import DepthCamera, get_world, simulate

    world, cam = get_world("office"), DepthCamera()
    robot = simulate(world, 1, sensor=cam)[0]
    poses = [np.ascontiguousarray(p) for p in robot.gt_poses[:: max(1, len(robot) // frames)]]
    u, v = np.meshgrid(np.arange(cam.width), np.arange(cam.height))
    rays = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u, float)], -1)
    rays = rays.reshape(-1, 3)
    scene = world.scene

    def fps(render) -> float:
        render(poses[0])  # warm-up
        start = time.perf_counter()
        for p in poses:
            render(p)
        return len(poses) / (time.perf_counter() - start)

    tiled = fps(
        lambda p: scene.depth_image(
            p, cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height, cam.max_depth
        )
    )
    per_ray = fps(lambda p: scene.ranges(p, rays, cam.max_depth))
    rng = np.random.default_rng(0)
    sensor = fps(lambda p: cam.render(world, p, rng))
    a = scene.depth_image(
        poses[3], cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height, cam.max_depth
    )
    b = np.nan_to_num(scene.ranges(poses[3], rays, cam.max_depth)).reshape(a.shape)
    return {
        "fps_tiled": tiled,
        "fps_per_ray": per_ray,
        "speedup": tiled / per_ray,
        "fps_sensor_with_noise": sensor,
        "frames": len(poses),
        "same_image": bool(np.array_equal(a, b.astype(np.float32))),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.frames)))
        return
    result = {"world": "office", "width": 640, "height": 480, "cpus": os.cpu_count()}
    for key, threads in (("one_core", "1"), ("all_cores", str(os.cpu_count()))):
        env = dict(os.environ, RAYON_NUM_THREADS=threads)
        out = subprocess.run(
            [sys.executable, __file__, "--child", "--frames", str(args.frames)],
            env=env,
            check=True,
            capture_output=True,
            text=True,
        )
        result[key] = json.loads(out.stdout)
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
