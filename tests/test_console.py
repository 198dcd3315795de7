"""The web console as a person uses it: a real headless browser (Debian's Chromium driven by Playwright) on the page
of `cap console`, a process of its own, against the whole graph with the MuJoCo simulator in this process. What is
checked is what the person sees on the page and what the simulator did: camera pictures that change when the arm
moves, a typed command's code and outcome, the stop button halting the arm, approval holding a command until
approved and dropping it when rejected, and no camera picture on a page of another origin. The graph's RViz output
(markers, robot description) is read by a subscriber beside it.

Without Chromium (`make browser`) these tests are skipped, unless CAP_REQUIRE_BROWSER=1 (CI) makes that a failure.
"""
from __future__ import annotations

import http.server
import os
import pathlib
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
import xml.etree.ElementTree as ElementTree

import cv2
import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from cap_bringup.graph import Graph, GraphOptions
from cap_bringup.visualization_node import LATCHED_QOS
from cap_interfaces.msg import GraphNames
from cap_sim_bridge.world import ARM_JOINT_NAMES, GRIPPER_JOINT_NAMES
from conftest import next_domain_id

CHROMIUM = os.environ.get('CAP_CHROMIUM', '/usr/bin/chromium')
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not os.access(CHROMIUM, os.X_OK) and os.environ.get('CAP_REQUIRE_BROWSER') != '1',
                       reason=f'no Chromium at {CHROMIUM} (make browser installs it)'),
]
BROWSER_ARGS = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
                '--disable-component-update', '--disable-sync', '--no-first-run']
OBJECTS = 'red block, blue block, green block, red bowl, blue bowl'
SAID = 'putting the red block in the red bowl'
CASSETTE = f"""format: cap-llm-cassette/1
entries:
- lmp: tabletop_ui
  query: put the red block in the red bowl
  context: '*'
  source: written by hand for this test
  completion: |-
    say('{SAID}')
    put_first_on_second('red block', 'red bowl')
- lmp: tabletop_ui
  query: warm up, then stack the blocks
  context: '*'
  source: written by hand for this test
  completion: |-
    for lap in range(4):
        put_first_on_second('blue block', 'green block')
        put_first_on_second('blue block', 'blue bowl')
    put_first_on_second('blue block', 'green block')
    put_first_on_second('red block', 'blue block')
- lmp: tabletop_ui
  query: put the blue block in the blue bowl
  context: '*'
  source: written by hand for this test
  completion: |-
    put_first_on_second('blue block', 'blue bowl')
"""
FRONT = '/cap/sim/cameras/front/color'
TIMEOUT_MS = 120_000


def _wait(predicate, timeout: float = 120.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


class Rig:
    """The graph in this process, `cap console` beside it, a browser on its page, and an RViz-like subscriber."""

    def __init__(self, folder: pathlib.Path) -> None:
        self.browser = self.playwright = self.profile = self.console = self.graph = self.viewer = None
        self.context = Context()
        try:
            self._start(folder)
        except BaseException:
            self.close()
            raise

    def _start(self, folder: pathlib.Path) -> None:
        from playwright.sync_api import sync_playwright

        self.domain = next_domain_id()
        rclpy.init(context=self.context, domain_id=self.domain)
        cassette = folder / 'console.yaml'
        cassette.write_text(CASSETTE, encoding='utf-8')
        # Rehearsed on a twin when approval is required: the approval shows the twin's picture.
        self.graph = Graph(self.context, GraphOptions(seed=2, objects=OBJECTS, cassette=str(cassette),
                                                      rehearse='on_approval'))
        self.world = self.graph.world
        self.lmp = self.graph.nodes['lmp_node']
        self.markers: list[MarkerArray] = []
        self.descriptions: list[str] = []
        self.viewer = rclpy.create_node('rviz_like_viewer', context=self.context)
        self.viewer.create_subscription(MarkerArray, GraphNames.MARKERS_TOPIC, self.markers.append, LATCHED_QOS)
        self.viewer.create_subscription(String, GraphNames.ROBOT_DESCRIPTION_TOPIC,
                                        lambda m: self.descriptions.append(m.data), LATCHED_QOS)
        self.graph.events_executor.add_node(self.viewer)
        env = {**os.environ, 'ROS_DOMAIN_ID': str(self.domain), 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
        self.console = subprocess.Popen([sys.executable, '-m', 'cap_bringup.cli', 'console', '--port', '0'],
                                        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.console_output: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read_console, daemon=True).start()
        self.url = self._console_url()
        self.profile = tempfile.TemporaryDirectory()
        self.playwright = sync_playwright().start()
        self.browser = self.playwright.chromium.launch_persistent_context(
            self.profile.name, executable_path=CHROMIUM, headless=True, args=BROWSER_ARGS,
            viewport={'width': 1400, 'height': 900},
            # The page's policy forbids evaluated script, which the test's own probes are; without the policy, a
            # page that turned text into markup would also run its scripts: the markup test sees that.
            bypass_csp=True)
        self.page = self.browser.new_page()
        self.page.set_default_timeout(TIMEOUT_MS)
        self.page.goto(self.url)
        # lmp_node's first status event on the page: the console's reply path to /cap/execute is open too.
        self.page.wait_for_function("document.getElementById('graph-state').textContent.includes('ready')")

    def _read_console(self) -> None:
        for line in self.console.stdout:
            self.console_output.put(line)

    def _console_url(self) -> str:
        while not (line := self.console_output.get(timeout=60)).startswith('console: '):
            pass  # the node's log lines
        assert line.startswith('console: http://127.0.0.1:'), line
        return line.split()[1]

    def run(self, command: str) -> None:
        self.page.fill('#command-input', command)
        self.page.click('#run-button')

    def entry(self, command: str):
        """The page's history entry of a command (the newest with that text)."""
        return self.page.locator('.history-entry', has=self.page.locator('.command', has_text=command)).first

    def front_picture(self) -> np.ndarray:
        png = self.page.locator(f'img[data-topic="{FRONT}"]').screenshot()
        return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_GRAYSCALE).astype(float)

    def close(self) -> int | None:
        """Close what was started; cap console's exit code (None if it was not started or had to be killed)."""
        for part, closing in ((self.browser, 'close'), (self.playwright, 'stop'), (self.profile, 'cleanup')):
            try:
                if part is not None:
                    getattr(part, closing)()
            except Exception:  # keep closing the rest
                pass
        code = None
        if self.console is not None:
            self.console.send_signal(signal.SIGTERM)
            try:
                code = self.console.wait(20)
            except subprocess.TimeoutExpired:
                self.console.kill()
                self.console.wait()
        if self.graph is not None:
            self.graph.close()
        if self.viewer is not None:
            self.viewer.destroy_node()
        self.context.try_shutdown()
        return code


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    built = Rig(tmp_path_factory.mktemp('console'))
    yield built
    assert built.close() == 0  # cap console ends cleanly on SIGTERM


def _distance_xy(world, first: str, second: str) -> float:
    a, b = world.object_state(first).position, world.object_state(second).position
    return float(np.linalg.norm(np.subtract(a[:2], b[:2])))


def test_the_page_shows_every_camera_and_a_typed_command_runs_with_its_code_words_and_outcome(rig):
    page = rig.page
    # Every camera the simulator publishes, found in the graph; depth listed but not streamed until asked for.
    page.wait_for_function(f"document.querySelector('img[data-topic=\"{FRONT}\"]')?.naturalWidth === 640")
    page.wait_for_function("document.querySelector('img[data-topic=\"/cap/sim/cameras/top/color\"]')?.naturalWidth")
    topics = page.eval_on_selector_all('figure', 'nodes => nodes.map(n => n.dataset.topic)')
    assert sorted(topics) == ['/cap/sim/cameras/front/color', '/cap/sim/cameras/front/depth',
                              '/cap/sim/cameras/top/color', '/cap/sim/cameras/top/depth']
    assert page.locator('img[data-topic="/cap/sim/cameras/top/depth"]').is_hidden()
    # The scene is at rest: the picture holds still.
    before = rig.front_picture()
    assert _wait(lambda: np.abs(rig.front_picture() - before).mean() < 0.5)
    arm_before = rig.world.joint_positions()

    rig.run('put the red block in the red bowl')
    entry = rig.entry('put the red block in the red bowl')
    entry.wait_for()
    assert entry.get_attribute('data-outcome') == 'done'
    assert "put_first_on_second('red block', 'red bowl')" in entry.locator('pre.code').text_content()
    assert entry.locator('ul.said li').all_text_contents() == [SAID]
    assert _distance_xy(rig.world, 'red block', 'red bowl') < 0.06  # it did what the page says
    assert not np.allclose(rig.world.joint_positions(), arm_before, atol=0.05)
    # The camera shows it: the arm and the block moved.
    assert _wait(lambda: np.abs(rig.front_picture() - before).mean() > 2.0)

    page.click('#reset-button')
    page.locator('#notices li', has_text='session reset').wait_for()


def test_text_from_commands_and_code_is_shown_as_text_never_as_markup(rig):
    command = '<img src=x onerror="document.title=1"><b id="injected">bold</b>'
    rig.run(command)
    entry = rig.entry('<b id="injected">')
    entry.wait_for()
    assert entry.get_attribute('data-outcome') == 'error'  # the cassette has no such program: a model error
    assert entry.locator('.command').text_content() == command
    assert rig.page.locator('#injected').count() == 0 and rig.page.title() == 'cap-ros console'


def test_the_stop_button_halts_the_arm_in_the_middle_of_a_motion(rig):
    world = rig.world
    # Ten motions: however slowly the browser's click arrives (a loaded machine), it lands inside the program.
    rig.run('warm up, then stack the blocks')
    assert _wait(lambda: np.max(np.abs(world.joint_velocities())) > 0.3)
    rig.page.click('#stop-button')
    entry = rig.entry('warm up, then stack the blocks')
    entry.wait_for()
    assert entry.get_attribute('data-outcome') == 'cancelled'
    assert 'stopped on /cap/stop' in entry.locator('.message').text_content()
    # On the simulator: the arm comes to rest and stays there, and the stack was not finished.
    assert _wait(lambda: np.max(np.abs(world.joint_velocities())) < 0.01)
    held, since = world.joint_positions(), world.time
    assert _wait(lambda: world.time > since + 1.0)
    assert np.allclose(world.joint_positions(), held, atol=1e-3)
    assert _distance_xy(world, 'red block', 'blue block') > 0.03


def test_approval_holds_a_command_until_approved_and_drops_it_when_rejected(rig):
    world, page = rig.world, rig.page
    rig.lmp.set_parameters([Parameter('require_approval', value=True)])
    try:
        start = world.object_state('blue block').position
        rig.run('put the blue block in the blue bowl')
        page.locator('#approval').wait_for()
        assert page.locator('#plan li').all_text_contents() == ['put the blue block on the blue bowl']
        # The rehearsal on the twin: its picture beside the live cameras, its summary in the message.
        page.locator('#twin-image').wait_for()
        assert _wait(lambda: page.evaluate("document.getElementById('twin-image').naturalWidth") == 320, 30)
        assert 'rehearsed on the twin (1 action(s)' in page.text_content('#current-message')
        assert "put_first_on_second('blue block', 'blue bowl')" in page.text_content('#current-code')
        # Held: simulated time passes, nothing moves, the command still waits.
        arm, since = world.joint_positions(), world.time
        assert _wait(lambda: world.time > since + 2.0)
        assert np.allclose(world.joint_positions(), arm, atol=1e-3)
        assert np.allclose(world.object_state('blue block').position, start, atol=1e-3)
        assert page.is_visible('#approval')
        # RViz sees the plan: an arrow from the blue block to the blue bowl.
        assert _wait(lambda: _plan_arrows(rig.markers[-1]) if rig.markers else False, 30)
        (arrow,) = _plan_arrows(rig.markers[-1])
        block, bowl = world.object_state('blue block').position, world.object_state('blue bowl').position
        assert np.allclose([arrow.points[0].x, arrow.points[0].y], block[:2], atol=0.01)
        assert np.allclose([arrow.points[1].x, arrow.points[1].y], bowl[:2], atol=0.01)

        page.click('#approve-button')
        entry = rig.entry('put the blue block in the blue bowl')
        entry.wait_for()
        assert entry.get_attribute('data-outcome') == 'done'
        assert _distance_xy(world, 'blue block', 'blue bowl') < 0.06

        placed = {state.name: state.position for state in world.object_states()}
        rig.run('put the red block in the red bowl')
        page.locator('#approval').wait_for()
        page.click('#reject-button')
        rejected = rig.page.locator('.history-entry[data-outcome="refused"]').first
        rejected.wait_for()
        assert 'rejected in the console' in rejected.locator('.message').text_content()
        assert all(np.allclose(world.object_state(name).position, position, atol=0.005)
                   for name, position in placed.items())
    finally:
        rig.lmp.set_parameters([Parameter('require_approval', value=False)])


class _OtherPage(http.server.BaseHTTPRequestHandler):
    """Another local page (another port of this host: another origin of the same site): `html` at every path."""

    html = ''

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        body = self.html.encode()
        self.send_response(200)
        self.send_header('Content-Type', 'text/html; charset=utf-8')
        self.send_header('Content-Length', str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *_: object) -> None:
        pass


def test_another_local_page_cannot_show_the_console_cameras(rig):
    page = rig.page
    page.wait_for_function(f"document.querySelector('img[data-topic=\"{FRONT}\"]')?.naturalWidth === 640")
    token = page.eval_on_selector('meta[name="cap-page-token"]', 'meta => meta.content')
    port = rig.url.rstrip('/').rsplit(':', 1)[1]
    # An <img> sends no Origin header. Guessed: without the token; the last two even with it (read somehow).
    addresses = {'guessed': f'http://127.0.0.1:{port}/stream{FRONT}',
                 'with-token': f'http://127.0.0.1:{port}/stream{FRONT}?token={token}',
                 'by-name': f'http://localhost:{port}/stream{FRONT}?token={token}'}
    _OtherPage.html = '<!DOCTYPE html><title>another page</title>' + ''.join(
        f'<img id="{name}" src="{url}" onload="this.dataset.ended=\'load\'" onerror="this.dataset.ended=\'error\'">'
        for name, url in addresses.items())
    server = http.server.ThreadingHTTPServer(('127.0.0.1', 0), _OtherPage)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    other = rig.browser.new_page()
    try:
        other.goto(f'http://127.0.0.1:{server.server_address[1]}/')
        other.wait_for_function('Array.from(document.images).every(image => image.dataset.ended)')
        ended = other.eval_on_selector_all('img', 'images => images.map(i => [i.id, i.dataset.ended, i.naturalWidth])')
        assert ended == [[name, 'error', 0] for name in addresses]
        # The console's own page still shows the camera.
        assert page.eval_on_selector(f'img[data-topic="{FRONT}"]', 'image => image.naturalWidth') == 640
    finally:
        other.close()
        server.shutdown()
        server.server_close()


def _plan_arrows(markers: MarkerArray) -> list[Marker]:
    return [m for m in markers.markers if m.ns == 'plan' and m.type == Marker.ARROW]


def test_rviz_gets_the_perceived_objects_by_name_and_the_robot_description(rig):
    source = rig.graph.nodes['perception_node'].source

    def names_shown() -> set[str]:
        return {m.text for m in rig.markers[-1].markers if m.ns == 'object_names'} if rig.markers else set()

    assert _wait(lambda: names_shown() == set(source.names()), 30)
    latest = rig.markers[-1].markers
    for marker in (m for m in latest if m.ns == 'object_names'):
        perceived = source.state(marker.text)
        assert np.allclose([marker.pose.position.x, marker.pose.position.y], perceived.position[:2], atol=1e-6)
    assert [m for m in latest if m.ns == 'workspace'][0].points[0].x == -0.3
    assert _wait(lambda: bool(rig.descriptions), 30)
    urdf = ElementTree.fromstring(rig.descriptions[-1])
    moving = [joint.get('name') for joint in urdf.findall('joint') if joint.get('type') != 'fixed']
    assert moving == list(ARM_JOINT_NAMES + GRIPPER_JOINT_NAMES)  # what /joint_states drives
