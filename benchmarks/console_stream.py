"""What watching the robot in the web console costs the simulator, and how fresh its pictures are.

The graph runs in this process as `cap up` runs it (pinned to the first CPU), simulating as fast as possible: then
its real-time factor (simulated seconds per wall second) drops with every bit of CPU or interpreter time taken from
it, so it is the sensitive measure (in real time the factor is 1.0 as long as the graph keeps up at all). `cap
console` runs in a process of its own on the other CPUs, as `cap up --console` starts it, and so does the viewer.

Windows of `--seconds` alternate (none, browser, none, browser, ...) so that load from elsewhere on the machine
falls on both alike, and besides the real-time factor each window reports the graph process' CPU time per simulated
second, which other processes taking the CPU from it do not change (the real-time factor of a graph that has its CPU
to itself is its inverse):
- none: nobody watches (the console runs, subscribed to no image);
- browser: Debian's headless Chromium shows the console page, which streams every colour camera (front and top).
Then the stream itself: a client reads the front camera's MJPEG stream for `--seconds` and counts frames; latency
is, per frame, its arrival at the client minus the arrival of the same image (same stamp) at a subscriber in the
graph's process, i.e. DDS to another process, JPEG encoding, HTTP.

Prints one JSON object. Run: source scripts/env.sh && ROS_DOMAIN_ID=64 python benchmarks/console_stream.py
(`--viewer URL` and `--client URL` are the helper modes it starts itself.)
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
CHROMIUM = os.environ.get('CAP_CHROMIUM', '/usr/bin/chromium')
BROWSER_ARGS = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
                '--disable-component-update', '--disable-sync', '--no-first-run']
FRONT = '/cap/sim/cameras/front/color'


# ------------------------------------------------------------------------------------------------ helper processes
def view(url: str, seconds: float) -> None:
    """Keep the console page open in headless Chromium for `seconds`; print how many pictures it showed."""
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as profile, sync_playwright() as playwright:
        browser = playwright.chromium.launch_persistent_context(profile, executable_path=CHROMIUM, headless=True,
                                                                args=BROWSER_ARGS, bypass_csp=True)
        page = browser.new_page()
        page.goto(url)
        page.wait_for_function(f"document.querySelector('img[data-topic=\"{FRONT}\"]')?.naturalWidth > 0",
                               timeout=60_000)
        print('watching', flush=True)
        time.sleep(seconds)
        browser.close()


def read_stream(url: str, seconds: float) -> None:
    """Read one MJPEG stream for `seconds`; print JSON: [[stamp, arrival time], ...] per frame."""
    frames = []
    with urllib.request.urlopen(url, timeout=30) as stream:
        deadline = time.time() + seconds
        while time.time() < deadline:
            line = stream.readline()
            if not line.startswith(b'Content-Type: image/jpeg'):
                continue
            headers = {}
            while (line := stream.readline()) != b'\r\n':
                name, _, value = line.decode().partition(':')
                headers[name] = value.strip()
            stream.read(int(headers['Content-Length']))
            frames.append([float(headers['X-Stamp']), time.time()])
    print(json.dumps(frames), flush=True)


# ------------------------------------------------------------------------------------------------ the benchmark
def helper(mode: str, url: str, seconds: float, cpus: set[int] | None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, __file__, mode, url, '--seconds', str(seconds)], stdout=subprocess.PIPE,
                            text=True, preexec_fn=(lambda: os.sched_setaffinity(0, cpus)) if cpus else None)


def window(world, seconds: float) -> tuple[float, float]:
    """(real-time factor, CPU seconds of this process per simulated second) over `seconds` of wall time."""
    sim, wall, cpu = world.time, time.monotonic(), time.process_time()
    time.sleep(seconds)
    simulated = world.time - sim
    return simulated / (time.monotonic() - wall), (time.process_time() - cpu) / simulated


def summary(alone: list[tuple[float, float]], watched: list[tuple[float, float]]) -> dict:
    def mean(values: list[tuple[float, float]], index: int) -> float:
        return statistics.mean(value[index] for value in values)

    rtf_alone, rtf_watched, cpu_alone, cpu_watched = mean(alone, 0), mean(watched, 0), mean(alone, 1), mean(watched, 1)
    return {'nobody_watching': [round(v, 2) for v, _ in alone],
            'one_browser_watching': [round(v, 2) for v, _ in watched],
            'mean_nobody_watching': round(rtf_alone, 2), 'mean_one_browser_watching': round(rtf_watched, 2),
            'change_percent': round(100 * (rtf_watched - rtf_alone) / rtf_alone, 1),
            'cpu_s_per_simulated_s': {'nobody_watching': round(cpu_alone, 3),
                                      'one_browser_watching': round(cpu_watched, 3),
                                      'change_percent': round(100 * (cpu_watched - cpu_alone) / cpu_alone, 1)}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--viewer', help=argparse.SUPPRESS)
    parser.add_argument('--client', help=argparse.SUPPRESS)
    parser.add_argument('--seconds', type=float, default=20.0, help='length of each window [20 s]')
    parser.add_argument('--rounds', type=int, default=4, help='pairs of windows without and with a browser [4]')
    args = parser.parse_args()
    if args.viewer:
        return view(args.viewer, args.seconds)
    if args.client:
        return read_stream(args.client, args.seconds)

    import rclpy
    from rclpy.context import Context
    from sensor_msgs.msg import Image

    from cap_bringup.console.node import STREAM_QOS
    from cap_bringup.cpu_affinity import cpus_besides
    from cap_bringup.graph import Graph, GraphOptions
    from cap_ros_common.time import to_seconds

    cpus = set(cpus_besides(0, list(os.sched_getaffinity(0)))) or None  # the graph takes the first CPU
    # Before the graph pins this process: the console gets the other CPUs, as with `cap up --console`.
    console = subprocess.Popen([sys.executable, '-m', 'cap_bringup.cli', 'console', '--port', '0'],
                               stdout=subprocess.PIPE, text=True,
                               preexec_fn=(lambda: os.sched_setaffinity(0, cpus)) if cpus else None)
    url = next(line for line in console.stdout if line.startswith('console: ')).split()[1]
    threading.Thread(target=console.stdout.read, daemon=True).start()
    context = Context()
    rclpy.init(context=context)
    graph = Graph(context, GraphOptions(seed=1))
    result: dict = {'graph': 'cap up --fast (as fast as possible), pinned to one CPU', 'console': url,
                    'console_cpus': sorted(cpus) if cpus else 'shared', 'seconds_per_window': args.seconds,
                    'load_average_before': os.getloadavg()[0]}
    try:
        world = graph.world
        time.sleep(5.0)  # settle: discovery, first frames
        alone, watched = [], []
        for _ in range(args.rounds):
            alone.append(window(world, args.seconds))
            viewer = helper('--viewer', url, args.seconds + 60, cpus)
            assert viewer.stdout.readline().strip() == 'watching'
            time.sleep(2.0)  # the page's streams are up
            watched.append(window(world, args.seconds))
            viewer.terminate()
            viewer.wait(30)
            time.sleep(2.0)  # its streams are closed and unsubscribed
        result['real_time_factor'] = summary(alone, watched)

        arrived: dict[float, float] = {}
        probe = rclpy.create_node('stream_probe', context=context)
        # Stamps to the microsecond, as the stream's X-Stamp header gives them.
        probe.create_subscription(Image, FRONT, lambda image: arrived.setdefault(
            round(to_seconds(image.header.stamp), 6), time.time()), STREAM_QOS)
        graph.events_executor.add_node(probe)
        client = helper('--client', f'{url}stream{FRONT}', args.seconds, cpus)
        frames = json.loads(client.communicate(timeout=args.seconds + 60)[0])
        latencies = sorted(1000 * (shown - arrived[round(stamp, 6)]) for stamp, shown in frames
                           if round(stamp, 6) in arrived)
        span = frames[-1][1] - frames[0][1] if len(frames) > 1 else 0.0
        result['front_camera_stream'] = {
            'frames': len(frames), 'frames_per_second': round((len(frames) - 1) / span, 2) if span else 0.0,
            'published_per_second': round(len(arrived) / args.seconds, 1),
            'latency_ms_median': round(statistics.median(latencies), 1) if latencies else None,
            'latency_ms_p95': round(latencies[int(0.95 * (len(latencies) - 1))], 1) if latencies else None,
            'frames_matched': len(latencies)}
        graph.events_executor.remove_node(probe)
        probe.destroy_node()
        result['load_average_after'] = os.getloadavg()[0]
    finally:
        console.terminate()
        console.wait(20)
        graph.close()
        context.try_shutdown()
    print(json.dumps(result, indent=2))


if __name__ == '__main__':
    main()
