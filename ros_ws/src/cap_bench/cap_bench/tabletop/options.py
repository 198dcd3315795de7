"""The table-top benchmark's options: the shared ones (cap_bench.bench_options) and its own: which rows (groups and
templates), the perception, the camera rate, and how many graphs run the episodes where (jobs, executor)."""
from __future__ import annotations

import dataclasses

from cap_bench.bench_options import BenchOptions
from cap_bench.tabletop.templates import GROUPS, TEMPLATES

# The benchmark's camera rate with the RGB-D detector. Perception analyses the newest frame only when asked, so a
# frame matters only at a question; rendering and sending a 640x480 colour and depth frame costs more than 15 steps
# of physics, and at 10 Hz it was a third of an RGB-D episode's wall time. At 2 Hz a question waits at most 0.5 s of
# simulated time for a frame newer than the last motion.
RGBD_CAMERA_RATE = 2.0


@dataclasses.dataclass
class TabletopOptions(BenchOptions):
    groups: tuple[str, ...] = tuple(GROUPS)
    tasks: tuple[str, ...] = tuple(TEMPLATES)
    perception: str = 'ground_truth'  # or 'rgbd'
    camera_rate: float = 0.0  # with perception rgbd [Hz of simulated time]; 0: RGBD_CAMERA_RATE
    jobs: int = 1  # parallel graphs: job i runs on first_domain_id + i
    executor: str = 'local'  # or 'ray' (cap_bench.tabletop.ray_executor)
    ray_address: str = ''  # for executor=ray: a cluster to join (host:6379); empty: a Ray instance for the run


def rgbd_camera_rate(options: TabletopOptions) -> float:
    """The bridge's camera rate for a run: 0 (no images) with ground truth."""
    if options.perception != 'rgbd':
        return 0.0
    return options.camera_rate or RGBD_CAMERA_RATE
