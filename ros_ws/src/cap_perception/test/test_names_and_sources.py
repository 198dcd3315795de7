"""Object names as users type them, and the sources behind the perception services."""
import dataclasses

import pytest

from cap_perception.names import UnknownObjectError, canonical_name, resolve_name
from cap_perception.objects import PerceivedObject
from cap_perception.sources import (CameraMemory, NoObservationError, SnapshotSource, load_stub_objects,
                                    remember_unseen)


@pytest.mark.parametrize('typed', ['red block', 'the red block', 'Red_Block', 'THE  red-block', 'red cube'])
def test_typed_names_mean_the_canonical_name(typed):
    assert resolve_name(typed, ['red block', 'red bowl', 'blue block']) == 'red block'


def test_grey_is_gray():
    assert canonical_name('the grey bowl') == 'gray bowl'


def test_unknown_name_error_lists_known_objects_and_a_close_match():
    with pytest.raises(UnknownObjectError) as error:
        resolve_name('red blok', ['red block', 'blue bowl'])
    assert "'red blok'" in str(error.value)
    assert "Did you mean 'red block'?" in str(error.value)
    assert 'blue bowl' in str(error.value)


def test_unknown_colour_gets_no_guess():
    with pytest.raises(UnknownObjectError, match='Known objects: blue bowl, red block') as error:
        resolve_name('purple block', ['red block', 'blue bowl'])
    assert 'Did you mean' not in str(error.value)


def test_snapshot_source_answers_from_its_latest_update():
    source = SnapshotSource('a test feed')
    with pytest.raises(NoObservationError, match='a test feed'):
        source.names()
    red = PerceivedObject.from_fields('red', 'block', (0.1, -0.5, 0.02), (0.04, 0.04, 0.04))
    hidden = PerceivedObject.from_fields('blue', 'bowl', (-0.1, -0.4, 0.03), (0.14, 0.14, 0.06), visible=False)
    source.update([red, hidden], stamp=2.5)
    assert source.names() == ['blue bowl', 'red block']
    assert source.names(visible_only=True) == ['red block']
    assert source.state('the Red_Block').bbox_min == pytest.approx((0.08, -0.52, 0.0))
    assert source.stamped_state('red block') == (red, 2.5)
    source.update([hidden], stamp=3.0)
    with pytest.raises(UnknownObjectError):
        source.state('red block')
    assert source.stamp == 3.0


def test_stub_file_loads_objects(tmp_path):
    stub = tmp_path / 'objects.yaml'
    stub.write_text('objects:\n'
                    '  - {color: green, category: block, position: [0.0, -0.6, 0.02]}\n'
                    '  - {color: yellow, category: bowl, position: [0.1, -0.4, 0.03], size: [0.14, 0.14, 0.06]}\n')
    objects = load_stub_objects(stub)
    assert [obj.name for obj in objects] == ['green block', 'yellow bowl']
    assert objects[0].bbox_max == pytest.approx((0.02, -0.58, 0.04))
    assert objects[1].color_rgba[:3] == pytest.approx((237 / 255, 201 / 255, 72 / 255))


@pytest.mark.parametrize('body, complaint', [
    ('objects:\n  - {color: magenta, category: block, position: [0, -0.5, 0.02]}\n', 'unknown colour'),
    ('objects:\n  - {color: red, category: sphere, position: [0, -0.5, 0.02]}\n', 'unknown object category'),
    ('objects:\n  - {color: red, category: block}\n', 'object #1 is invalid'),
    ('objects:\n  - {color: red, category: block, position: [0, 0, 0]}\n'
     '  - {color: red, category: block, position: [0.2, 0, 0]}\n', 'repeated: red block'),
    ('objects: [unclosed\n', 'cannot read'),
])
def test_bad_stub_files_are_refused_with_a_reason(tmp_path, body, complaint):
    stub = tmp_path / 'objects.yaml'
    stub.write_text(body)
    with pytest.raises(ValueError, match=complaint):
        load_stub_objects(stub)


def test_objects_hidden_from_the_camera_stay_known_as_not_visible():
    red = PerceivedObject.from_fields('red', 'block', (0.1, -0.5, 0.02), (0.04,) * 3)
    blue = PerceivedObject.from_fields('blue', 'block', (0.0, -0.4, 0.02), (0.04,) * 3)
    moved_red = PerceivedObject.from_fields('red', 'block', (0.0, -0.4, 0.06), (0.04,) * 3)
    merged = remember_unseen([red, blue], [moved_red])  # red now sits on blue and hides it
    assert [(o.name, o.visible, o.position) for o in merged] == [
        ('blue block', False, blue.position), ('red block', True, moved_red.position)]


def test_frames_of_the_old_scene_leave_nothing_behind_after_a_forget():
    old = PerceivedObject.from_fields('cyan', 'block', (0.1, -0.5, 0.02), (0.04,) * 3)
    new = PerceivedObject.from_fields('red', 'block', (0.0, -0.4, 0.02), (0.04,) * 3)
    wall = [1_000]
    memory = CameraMemory(SnapshotSource('camera'), settle_s=1.0, wall_clock_ns=lambda: wall[0])
    memory.record(memory.begin(1.0, received_ns=900), 1.0, [old])
    in_flight = memory.begin(1.1, received_ns=950)  # an analysis of the old scene running when it is reset
    wall[0] = 2_000
    memory.forget()
    memory.record(in_flight, 1.1, [old])
    assert memory.source.objects() == []
    assert memory.begin(1.2, received_ns=1_500) is None  # queued before the forget: the old scene
    memory.record(memory.begin(5.0, received_ns=2_100), 5.0, [new])
    assert [o.name for o in memory.source.objects()] == ['red block']


def test_after_a_forget_only_a_short_stretch_of_frame_time_replaces_the_objects():
    # Frames are analysed when asked for: a window counted in frames would last as long as nobody asks, and a
    # frame taken while the arm carries or hides a block would drop that block.
    red = PerceivedObject.from_fields('red', 'block', (0.0, -0.4, 0.02), (0.04,) * 3)
    blue = PerceivedObject.from_fields('blue', 'block', (0.1, -0.6, 0.02), (0.04,) * 3)
    memory = CameraMemory(SnapshotSource('camera'), settle_s=1.0)
    memory.forget()
    memory.record(memory.begin(10.0), 10.0, [red, blue])
    memory.record(memory.begin(10.5), 10.5, [blue])  # within the window: replaces
    assert [o.name for o in memory.source.objects()] == ['blue block']
    memory.record(memory.begin(10.9), 10.9, [red, blue])
    memory.record(memory.begin(11.8), 11.8, [blue])  # settled: the red block, hidden now, is remembered
    assert [(o.name, o.visible) for o in memory.source.objects()] == [('blue block', True), ('red block', False)]


def test_frames_are_analysed_only_when_asked_and_then_the_newest():
    red = PerceivedObject.from_fields('red', 'block', (0.0, -0.4, 0.02), (0.04,) * 3)
    analysed = []

    def analyse(frame):
        analysed.append(frame)
        return [dataclasses.replace(red, position=(frame, -0.4, 0.02))]

    source = SnapshotSource('camera')
    memory = CameraMemory(source, analyse=analyse)
    for stamp in (1.0, 1.1, 1.2):  # a camera's stream: nobody asks, nothing is analysed
        memory.offer(stamp, stamp)
    assert analysed == []
    assert source.state('red block').position[0] == 1.2  # asked: the newest frame only
    assert source.names() == ['red block'] and analysed == [1.2]  # asked again, no newer frame: no new analysis
    memory.offer(1.3, 1.3)
    memory.offer(1.25, 1.25)  # late and older: not kept
    _, stamp = source.stamped_state('the red block')
    assert stamp == 1.3 and analysed == [1.2, 1.3]
    memory.forget()
    with pytest.raises(NoObservationError):  # nothing newer than the forget yet
        source.names()
