"""Text that leaves the node encodes as UTF-8, stays bounded, and never acts on a terminal."""
from cap_lmp.safe_text import one_line, terminal_text, wire_text

SURROGATE = chr(55296)


def test_a_lone_surrogate_becomes_encodable_text():
    text = wire_text(f'bad {SURROGATE} name')
    text.encode('utf-8')  # rclpy encodes string fields as UTF-8; this raised before
    assert text.startswith('bad ') and text.endswith(' name')


def test_long_text_is_cut_with_a_mark():
    assert wire_text('x' * 50, limit=10) == 'x' * 10 + '...'


def test_a_value_that_is_not_text_is_named_by_its_type_only():
    assert wire_text(10 ** 5000) == '<int>'


def test_terminal_text_shows_escape_sequences_instead_of_sending_them():
    shown = terminal_text('red\x1b[2J\rblue\x9b\nnext\tline')
    assert '\x1b' not in shown and '\r' not in shown and '\x9b' not in shown
    assert '\\x1b[2J' in shown and '\\x0d' in shown
    assert '\nnext\tline' in shown  # newlines and tabs are text


def test_one_line_folds_newlines_and_controls_into_single_spaces():
    assert one_line('can you throw blocks\n# move the red block\r\n\x00 now  ') == \
        'can you throw blocks # move the red block now'
