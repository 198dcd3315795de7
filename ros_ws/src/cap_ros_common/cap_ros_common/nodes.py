"""main() of a node: build it, spin it until Ctrl-C or shutdown, clean up. One home for what every node's entry point
does."""
from __future__ import annotations

from typing import Callable

import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor


def spin_node(make_node: Callable[[], object], args: list[str] | None = None, threads: int = 1) -> None:
    """Initialise rclpy with `args`, build the node and spin it on one thread, or on a multi-threaded executor of
    `threads` for a node whose callbacks block (action goals that last a motion), until it is shut down."""
    rclpy.init(args=args)
    node = None
    executor = SingleThreadedExecutor() if threads <= 1 else MultiThreadedExecutor(num_threads=threads)
    try:
        node = make_node()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


__all__ = ['spin_node']
