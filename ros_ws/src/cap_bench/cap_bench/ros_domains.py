"""Which ROS_DOMAIN_ID each graph of a benchmark run uses: consecutive ids, so that parallel graphs never meet."""
from __future__ import annotations

import os

MAX_DOMAIN_ID = 232  # the largest ROS_DOMAIN_ID whose DDS ports are valid


def domain_ids(jobs: int, first: int | None = None, environ: dict[str, str] | None = None) -> list[int]:
    """The ROS_DOMAIN_ID of each of `jobs` parallel graphs: consecutive ids from `first`, else from the
    environment's ROS_DOMAIN_ID, else from a process-id-dependent start in 1..101."""
    environ = os.environ if environ is None else environ
    jobs = max(1, jobs)
    if first is None and environ.get('ROS_DOMAIN_ID', '').strip():
        text = environ['ROS_DOMAIN_ID'].strip()
        if not text.isdigit():
            raise ValueError(f'ROS_DOMAIN_ID={text!r} is not a domain id (an integer in 0..{MAX_DOMAIN_ID})')
        first = int(text)
    if first is None:
        first = 1 + os.getpid() % max(1, 101 - jobs)
    if first < 0 or first + jobs - 1 > MAX_DOMAIN_ID:
        raise ValueError(f'{jobs} job(s) need ROS_DOMAIN_IDs {first}..{first + jobs - 1}, beyond 0..{MAX_DOMAIN_ID}:'
                         f' choose a smaller ROS_DOMAIN_ID or fewer --jobs')
    return list(range(first, first + jobs))


def use_own_domain(domain_id: int) -> None:
    """Keep the graphs this process brings up on DDS domain `domain_id`, discovered on this host only (set before
    rclpy starts)."""
    os.environ['ROS_DOMAIN_ID'] = str(domain_id)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
