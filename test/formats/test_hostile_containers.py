"""
Damaged bag containers: identical samples, or a warning naming the damage, or InputError.

Never a changed result without a warning.  Each storage is written once with the package's
own writer (MCAP chunks now carry real CRC-32s) and damaged with seeded byte flips over the
whole file (40 variants of 20 flips, as the hostile probes did).  Bags hold 3,000 samples;
the whole file runs in a few seconds.
"""

import shutil

from formats.flip_cases import flipped, outcome
from imu_allan.formats.bag_reader import read_bag
from imu_allan.formats.bag_writer import encode_imu, write_imu_bag
from imu_allan.formats.mcap_scan import McapScan
from imu_allan.formats.samples import Samples
import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.typesys import get_typestore, Stores

N = 3000


def _samples():
    rng = np.random.default_rng(0)
    return Samples(t=1.7e9 + np.arange(N) / 100.0, data=rng.normal(0.0, 1e-3, (N, 6)))


def _outcome(path, ref):
    """Return 'same', 'warned' or 'refused'; fails on a changed result without a warning."""
    result = outcome(path, ref)  # flip_cases' reading: 'silent' is a change without warning
    if result == 'silent':  # allowed only where the container has no checksums to tell
        assert 'no checksums' in read_bag(path).integrity, 'changed result, no warning'
        return 'warned'
    return result


def test_own_mcap_writer_stores_chunk_crcs(tmp_path):
    """Every chunk of the package's MCAP has a CRC, and rosbags (which checks it) reads it."""
    folder = write_imu_bag(tmp_path / 'bag', _samples(), storage='mcap')
    scan = McapScan(str(next(folder.glob('*.mcap'))))
    scan.run()
    assert scan.chunks_without_crc == 0 and not scan.warnings
    with Rosbag2Reader(folder) as reader:
        assert sum(1 for _ in reader.messages()) == N


def test_mcap_damaged_chunk_named_with_its_lost_messages(tmp_path):
    """A flipped byte in a chunk: that chunk is skipped (CRC), its loss counted, the rest kept."""
    samples = _samples()
    folder = write_imu_bag(tmp_path / 'bag', samples, storage='mcap')
    src = next(folder.glob('*.mcap'))
    scan = McapScan(str(src))
    scan.run()
    assert len(scan.chunk_offsets) >= 2
    raw = bytearray(src.read_bytes())
    first = scan.chunk_offsets[0]
    raw[first + 500] ^= 0x10
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(bytes(raw))
    got = read_bag(bad)
    lost = N - got.n
    assert 0 < lost < N
    assert any(f'chunk 1 of {len(scan.chunk_offsets)}: {lost} Imu message(s) lost' in w
               for w in got.warnings), got.warnings


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_byte_flips_never_change_the_result_silently(tmp_path, storage):
    """MCAP: every damaged chunk is detected by its CRC; sqlite3 (no checksums) says so."""
    folder = write_imu_bag(tmp_path / 'bag', _samples(), storage=storage)
    src = next(p for p in folder.iterdir() if p.suffix in ('.mcap', '.db3'))
    ref = read_bag(src)
    raw = src.read_bytes()
    outcomes = []
    for seed in range(40):
        path = tmp_path / f'damaged{seed}{src.suffix}'
        path.write_bytes(flipped(raw, seed))
        outcomes.append(_outcome(path, ref))
    if storage == 'mcap':
        assert 'no checksums' not in ref.integrity
        assert outcomes.count('warned') + outcomes.count('refused') >= 30
    else:
        assert 'no checksums' in ref.integrity


def _ros1_bag(path):
    """Return a ROS 1 bag with lz4 chunks of about 270 messages (11 chunks)."""
    rows, stamps = encode_imu(_samples().t, _samples().data, ros1=True)
    writer = Ros1Writer(path)
    writer.set_compression(Ros1Writer.CompressionFormat.LZ4)
    writer.chunk_threshold = 100_000
    store = get_typestore(Stores.ROS1_NOETIC)
    with writer:
        conn = writer.add_connection('/imu', 'sensor_msgs/msg/Imu', typestore=store)
        for stamp, row in zip(stamps.tolist(), rows):
            writer.write(conn, stamp, row.tobytes())
    return path


def _chunk_data_offsets(raw):
    """Byte offsets of each chunk record and of its data, from the ROS 1 record headers."""
    pos, out = 13, []
    while pos < len(raw):
        hlen = int.from_bytes(raw[pos:pos + 4], 'little')
        head = raw[pos + 4:pos + 4 + hlen]
        dlen = int.from_bytes(raw[pos + 4 + hlen:pos + 8 + hlen], 'little')
        if b'op=\x05' in head:
            out.append((pos, pos + 8 + hlen))
        pos += 8 + hlen + dlen
    return out


def test_ros1_flips_inside_chunks_warn_or_are_declared_unverifiable(tmp_path):
    """LZ4 without a content checksum may decode a flipped literal: the report says so."""
    path = _ros1_bag(tmp_path / 'ok.bag')
    ref, raw = read_bag(path), path.read_bytes()
    assert 'no checksums' in ref.integrity
    for seed in range(20):
        bad = tmp_path / f'bad{seed}.bag'
        bad.write_bytes(flipped(raw, seed, flips=5))
        _outcome(bad, ref)


@pytest.mark.parametrize('which', ['first', 'middle'])
def test_ros1_damaged_chunk_skipped_rest_kept(tmp_path, which):
    """A damaged compressed chunk costs its own messages only, named with its position."""
    path = _ros1_bag(tmp_path / 'ok.bag')
    raw = path.read_bytes()
    chunks = _chunk_data_offsets(raw)
    k = 0 if which == 'first' else len(chunks) // 2
    for seed in range(4):  # each byte of the chunk's LZ4 frame magic: decompression fails
        buf = bytearray(raw)
        buf[chunks[k][1] + seed] ^= 0xFF
        bad = tmp_path / f'bad{seed}.bag'
        bad.write_bytes(bytes(buf))
        got = read_bag(bad)
        assert N * 0.85 < got.n < N
        text = ' '.join(got.warnings)
        assert f'chunk {k + 1} of {len(chunks)}' in text and 'lost' in text
        assert f'{N - got.n} of its' in text


def test_rosbag2_metadata_naming_wrong_storage_trusts_the_file(tmp_path):
    """metadata.yaml says sqlite3, the file is MCAP: read it, warn about the metadata."""
    folder = write_imu_bag(tmp_path / 'bag', _samples(), storage='mcap')
    meta = folder / 'metadata.yaml'
    meta.write_text(meta.read_text().replace('storage_identifier: mcap',
                                             'storage_identifier: sqlite3'))
    got = read_bag(folder)
    assert got.n == N and any("names storage 'sqlite3'" in w for w in got.warnings)
    shutil.rmtree(folder)
