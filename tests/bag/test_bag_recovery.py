"""Damaged bags: truncated files, a missing metadata.yaml and a crash mid-split give back
every readable message and say where reading stopped."""

from __future__ import annotations

from pathlib import Path

from _support.bags import NS, T0, read_bag
from eddiebot.bag import (
    BagWriter,
    Player,
    bag_info,
    format_bag_info,
)
from eddiebot.core import (
    Context,
    SingleThreadedExecutor,
)
from eddiebot.msgs import deserialize, serialize
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.nav_msgs import Odometry


def test_truncated_bag_reports_and_recovers_prefix(recorded: Path, tmp_path: Path) -> None:
    # Many small chunks so a cut leaves whole chunks before it, as a crash after flushes.
    bag = tmp_path / "cut"
    with BagWriter(bag) as w:
        for k in range(200):
            w.write_message("/odom", Odometry(), T0 + k * NS // 100)
            if k % 20 == 19:
                w.flush()
    (mcap,) = bag.glob("*.mcap")
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    info = bag_info(bag)
    assert not info.complete
    (problem,) = info.problems
    assert problem.file == mcap
    assert problem.offset is not None
    assert 0 < problem.offset <= len(data) // 2
    assert 60 <= info.message_count < 200
    assert problem.message_index == info.message_count
    text = format_bag_info(info)
    assert "Damaged:" in text
    assert str(mcap) in text
    # the readable prefix is the original messages, in order
    got = read_bag(bag)
    assert [t for _, t, _ in got] == [T0 + k * NS // 100 for k in range(len(got))]
    assert all(d == serialize(Odometry()) for _, _, d in got)
    # playing it plays the prefix and says where it broke
    ctx = Context(use_sim_time=True)
    player = Player(bag, context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(player)
    ex.spin_for(5.0)
    assert player.done
    assert player.published == info.message_count
    assert player.problems == info.problems


def test_truncated_inside_unflushed_chunk(recorded: Path) -> None:
    """A recording cut inside its only (uncompressed) chunk still yields whole messages."""
    (mcap,) = recorded.glob("*.mcap")
    data = mcap.read_bytes()
    (recorded / "metadata.yaml").unlink()  # a crashed recorder never wrote it
    mcap.write_bytes(data[: len(data) // 2])
    info = bag_info(recorded)
    assert info.problems
    assert 5 < info.message_count < 40
    assert any("metadata.yaml" in n for n in info.notes)
    odom = [deserialize(d, "nav_msgs/msg/Odometry") for t, _, d in read_bag(recorded) if t == "/odom"]
    assert [round(o.pose.pose.position.x, 3) for o in odom] == [
        round(0.01 * (k + 1), 3) for k in range(len(odom))
    ]


def test_missing_metadata_reads_mcap_directly(recorded: Path) -> None:
    original = read_bag(recorded)
    (recorded / "metadata.yaml").unlink()
    info = bag_info(recorded)
    assert info.complete
    assert info.message_count == 40
    assert sorted(read_bag(recorded)) == sorted(original)


def test_crash_during_split_recording_recovers_every_flushed_message(tmp_path: Path) -> None:
    bag = tmp_path / "crash"
    w = BagWriter(bag, max_bag_duration=1.0)
    for k in range(25):
        w.write_message("/cmd_vel", Twist(), T0 + k * NS // 10)
    w.flush()  # what the recorder does every flush_interval; then the process dies
    assert sorted(p.name for p in bag.glob("*.mcap")) == ["crash_0.mcap", "crash_1.mcap",
                                                          "crash_2.mcap"]
    info = bag_info(bag)
    assert info.message_count == 25
    assert any("crash_2.mcap" in n for n in info.notes)
    (problem,) = info.problems
    assert problem.file.name == "crash_2.mcap"
    assert problem.message_index == 25
