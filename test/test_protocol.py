"""The serial line protocol (sma_wrist/hw/protocol.py, doc/explanation/protocol.md): round trip,
robustness against garbage, corruption, cut lines and chunking, sequence tracking."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from sma_wrist.hw import protocol as P

u16 = st.integers(0, P.ADC_MAX)
text = st.from_regex(r'[A-Za-z0-9_.\-]{0,40}', fullmatch=True)
samples = st.builds(
    P.Sample,
    st.integers(0, P.SEQ_MODULUS - 1),
    st.integers(0, (1 << 64) - 1),
    st.tuples(u16, u16, u16, u16, u16),
    st.integers(0, 0xFFFF),
    st.none() | st.tuples(st.integers(-P.MV_LIMIT, P.MV_LIMIT), st.integers(-P.MV_LIMIT, P.MV_LIMIT)),
)
frames = st.one_of(
    samples,
    st.builds(
        P.Command,
        st.integers(0, P.SEQ_MODULUS - 1),
        st.integers(-P.MV_LIMIT, P.MV_LIMIT),
        st.integers(-P.MV_LIMIT, P.MV_LIMIT),
    ),
    st.builds(P.Hello, text, text, st.integers(1, 100000)),
    st.builds(P.Reset, text),
    st.builds(P.Error, st.integers(0, 65535), text),
    st.just(P.Query()),
    st.builds(P.DriveReadback, st.booleans()),
)


def parse_all(data: bytes, chunks: list[int] | None = None) -> tuple[list[P.Frame], P.Parser]:
    p = P.Parser()
    out: list[P.Frame] = []
    if not chunks:
        return p.feed(data), p
    i = 0
    for c in chunks:
        out += p.feed(data[i : i + c])
        i += c
    out += p.feed(data[i:])
    return out, p


def test_crc_check_value_and_example_lines():
    assert P.crc16(b'123456789') == 0x29B1  # CRC-16/CCITT-FALSE check value
    # the examples of doc/explanation/protocol.md
    assert (
        P.encode(P.Sample(41, 41000, (25000, 24987, 17500, 17512, 35388), 0))
        == b'$S,1,41,41000,25000,24987,17500,17512,35388,0*'
        + b'%04X' % P.crc16(b'S,1,41,41000,25000,24987,17500,17512,35388,0')
        + b'\n'
    )
    assert P.Parser().feed(b'$C,1,7,-12000,13000*' + b'%04X' % P.crc16(b'C,1,7,-12000,13000') + b'\r\n') == [
        P.Command(7, -12000, 13000)
    ]


def test_a_sample_with_the_drive_read_back_and_one_without_both_parse():
    """The read-back is two optional fields at the end of S: a device without it (9 fields) parses as before, with
    ``drive_mV`` None; out of the command range, or only one of the two, is malformed."""
    old = P.encode_unchecked('S,1,41,41000,25000,24987,17500,17512,35388,0')
    new = P.encode_unchecked('S,1,41,41000,25000,24987,17500,17512,35388,2,-24000,13000')
    adc = (25000, 24987, 17500, 17512, 35388)
    assert P.Parser().feed(old + new) == [P.Sample(41, 41000, adc, 0), P.Sample(41, 41000, adc, 2, (-24000, 13000))]
    assert P.Parser().feed(P.encode_unchecked('D,1,1') + P.encode_unchecked('D,1,0')) == [
        P.DriveReadback(True),
        P.DriveReadback(False),
    ]
    p = P.Parser()
    bad = ('S,1,1,1,1,1,1,1,1,0,30001,0', 'S,1,1,1,1,1,1,1,1,0,5', 'S,1,1,1,1,1,1,1,1,0,-0,0', 'D,1,2')
    assert p.feed(b''.join(P.encode_unchecked(b) for b in bad)) == [] and p.stats.malformed == len(bad)
    longest = P.Sample(P.SEQ_MODULUS - 1, (1 << 64) - 1, (P.ADC_MAX,) * 5, 0xFFFF, (-P.MV_LIMIT, -P.MV_LIMIT))
    assert len(P.encode(longest)) <= P.MAX_LINE


@given(st.lists(frames, max_size=20), st.lists(st.integers(1, 40), max_size=30))
def test_round_trip_under_any_chunking(sent, chunks):
    data = b''.join(P.encode(f) for f in sent)
    got, p = parse_all(data, chunks)
    assert got == sent
    assert p.stats.rejected_lines == 0 and p.stats.garbage_bytes == 0


@settings(max_examples=300)
@given(st.lists(st.tuples(frames, st.binary(max_size=60)), max_size=15), st.lists(st.integers(1, 50), max_size=20))
def test_garbage_between_frames_never_yields_a_frame_that_was_not_sent(pairs, chunks):
    """Arbitrary bytes (also '$', '*', '\\n', digits) between lines: every returned frame was
    sent, in order; a frame is lost only when garbage cut its line (no newline in between)."""
    data = b''.join(g + P.encode(f) for f, g in pairs)
    got, p = parse_all(data, chunks)
    sent = [f for f, _ in pairs]
    it = iter(sent)
    assert all(any(g == s for s in it) for g in got), 'returned a frame that was not sent (or out of order)'
    # garbage without '$', or ending in a newline, cannot hurt the frame after it
    must = [f for f, g in pairs if b'$' not in g or g.endswith(b'\n')]
    it = iter(got)
    assert all(any(g == m for g in it) for m in must), 'lost a frame that garbage could not have damaged'


@settings(max_examples=300)
@given(frames, st.data())
def test_any_single_byte_corruption_is_detected(frame, data):
    line = P.encode(frame)
    i = data.draw(st.integers(0, len(line) - 2), label='position')  # the '\n' is framing, tested below
    b = data.draw(st.integers(0, 255).filter(lambda v: v != line[i]), label='byte')
    bad = line[:i] + bytes([b]) + line[i + 1 :]
    got, p = parse_all(bad + P.encode(P.Query()))
    assert got == [P.Query()]
    assert p.stats.rejected_lines + p.stats.garbage_bytes > 0


@given(frames, st.data())
def test_cut_lines_are_counted_not_returned(frame, data):
    line = P.encode(frame)
    k = data.draw(st.integers(1, len(line) - 1))
    nxt = P.Sample(1, 2, (3, 4, 5, 6, 7))
    got, p = parse_all(line[:k] + P.encode(nxt))
    assert got == [nxt]
    assert p.stats.partial_lines + p.stats.malformed + p.stats.bad_checksum + p.stats.garbage_bytes >= 1


def test_each_kind_of_damage_is_counted_once():
    good = P.encode(P.Sample(5, 5000, (1, 2, 3, 4, 5)))
    wrong_crc = good[:-5] + b'%04X\n' % ((int(good[-5:-1], 16) + 1) & 0xFFFF)
    cases = {
        'garbage_bytes': b'\x00\xffnoise',
        'partial_lines': good[:12],  # the next line's '$' cuts it
        'bad_checksum': wrong_crc,
        'malformed': b'$S,1,5,5000,1,2,3,4,5*\n',  # no checksum
        'version_mismatch': P.encode_unchecked('S,2,5,5000,1,2,3,4,5,0'),
        'overlong_lines': b'$' + b'1' * (P.MAX_LINE + 5),
    }
    for name, damage in cases.items():
        got, p = parse_all(damage + good)
        assert got == [P.Sample(5, 5000, (1, 2, 3, 4, 5))], name
        counted = {k: v for k, v in vars(p.stats).items() if v and k != 'frames'}
        assert list(counted) == [name] or (name == 'overlong_lines' and 'garbage_bytes' in counted), (name, counted)


def test_out_of_range_and_non_canonical_fields_are_rejected():
    bodies = [
        'S,1,5,5000,1,2,3,4,65536,0',  # ADC above 16 bits
        'S,1,05,5000,1,2,3,4,5,0',  # leading zero
        'S,1,+5,5000,1,2,3,4,5,0',
        'S,1,5,5_000,1,2,3,4,5,0',
        'S,1,5,5000,1,2,3,4,0',  # too few
        'S,1,4294967296,5000,1,2,3,4,5,0',  # sequence beyond 32 bits
        'C,1,1,30001,0',
        'C,1,1,-0,0',
        'X,1,2',
        'S,1,5,5000,1,2,3,4,5,0,9',
    ]
    for b in bodies:
        got, p = parse_all(P.encode_unchecked(b))
        assert got == [] and p.stats.malformed == 1, b


def test_lowercase_checksum_is_malformed():
    line = P.encode(P.Query())
    assert line == b'$Q,1*C09B\n'  # has hex letters
    got, p = parse_all(b'$Q,1*c09b\n')
    assert got == [] and p.stats.malformed == 1


def test_encode_refuses_out_of_range_frames():
    import pytest

    for f in (P.Sample(0, 0, (0, 0, 0, 0, 70000)), P.Command(0, 40000, 0), P.Reset('a,b'), P.Hello('x', 'y', 0)):
        with pytest.raises(ValueError):
            P.encode(f)


def test_sequence_tracker_gaps_repeats_and_wrap():
    t = P.SequenceTracker()
    assert [t.update(s) for s in (10, 11, 14, 14, 12, 15)] == [0, 0, 2, -1, -1, 0]
    assert (t.lost, t.gaps, t.backwards) == (2, 1, 2)
    t = P.SequenceTracker()
    assert [t.update(s) for s in (P.SEQ_MODULUS - 2, P.SEQ_MODULUS - 1, 0, 2)] == [0, 0, 0, 1]
