"""Memory management by weight, as RTAB-Map's `Memory`: rehearsal (`Mem/RehearsalSimilarity`)
raises the weight of a place seen again from the previous node, loop closures move weight to the
newer node, and transfer to LTM takes the lowest weight first, never nodes linked to STM, the
last loop closure's node or the recent part of WM. Nodes keep decimated, compressed images and
rebuild their cloud on demand."""

import numpy as np
from vslam_synthetic import frame, kinect_camera, planar_pose

from eddiebot.vslam.database import SessionDatabase
from eddiebot.vslam.features import FrameFeatures
from eddiebot.vslam.memory import Link, LinkType, Memory, Node, NodeData
from eddiebot.vslam.occupancy import CloudImages, depth_cloud, voxel_first_indices
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.vocabulary import Vocabulary

CAM = kinect_camera(320, 240)
BASE = {"RGBD/LinearUpdate": "0.05", "RGBD/ProximityBySpace": "false",
        "Reg/Force3DoF": "true", "Vis/MinInliers": "12"}


def _node(i: int, words: dict[int, int] | None = None, weight: int = 0) -> Node:
    return Node(i, 0, i, np.eye(4), weight=weight, word_counts=dict(words or {}),
                data=NodeData(FrameFeatures.empty(), np.zeros(0, np.int64)))


def _chain(n: int, stm_size: int) -> Memory:
    """Nodes 1..n linked by odometry, the last `stm_size` in STM."""
    mem = Memory(Vocabulary(0.8), stm_size)
    for i in range(1, n + 1):
        mem.add_to_stm(_node(i))
        if i > 1:
            mem.add_link(Link(i - 1, i, LinkType.NEIGHBOR, np.eye(4), np.eye(6)))
    return mem


def test_similarity_counts_word_pairs_over_the_larger_word_count():
    mem = Memory(Vocabulary(0.8), 10)
    a = _node(1, {1: 2, 2: 1, 3: 1})  # 4 words
    b = _node(2, {1: 1, 2: 1, 4: 3})  # 5 words
    # pairs: word 1 min(2, 1) + word 2 min(1, 1) = 2, over max(4, 5)
    assert mem.similarity(a, b) == 2 / 5 == mem.similarity(b, a)
    assert mem.similarity(a, _node(3)) == 0.0


def test_rehearsal_merges_a_repeat_when_not_moving_and_raises_the_weight():
    slam = Rtabmap(BASE)
    rgb, depth = frame(3, 2.0, 3.0, 0.0)
    first = slam.process(rgb, depth, CAM, planar_pose(0, 0, 0), 0)
    for k in range(1, 4):  # the same view, the robot still
        r = slam.process(rgb, depth, CAM, planar_pose(0.001 * k, 0, 0), k)
        assert not r.added
        assert r.statistics["Memory/Rehearsal_merged/"] == first.node_id
        assert r.statistics["Memory/Rehearsal_sim/"] > 0.9
    assert slam.memory.nodes[first.node_id].weight == 3
    assert list(slam.memory.nodes) == [first.node_id]


def test_rehearsal_while_moving_moves_the_weight_and_keeps_the_node():
    params = {**BASE, "RGBD/LinearUpdate": "0", "RGBD/AngularUpdate": "0"}
    rgb, depth = frame(3, 2.0, 3.0, 0.0)
    other_rgb, other_depth = frame(5, 1.0, 1.0, 2.0)
    slam = Rtabmap(params)
    a = slam.process(rgb, depth, CAM, planar_pose(0, 0, 0), 0)
    b = slam.process(rgb, depth, CAM, planar_pose(0.02, 0, 0), 1)  # similar, moving
    c = slam.process(other_rgb, other_depth, CAM, planar_pose(0.04, 0, 0), 2)  # different
    assert a.added and b.added and c.added
    assert b.statistics["Memory/Rehearsal_id/"] == a.node_id
    assert b.statistics["Memory/Rehearsal_merged/"] == 0
    assert c.statistics["Memory/Rehearsal_id/"] == 0
    assert c.statistics["Memory/Rehearsal_sim/"] < 0.2
    weights = {i: n.weight for i, n in slam.memory.nodes.items()}
    assert weights == {a.node_id: 1, b.node_id: 0, c.node_id: 0}
    ignored = Rtabmap({**params, "Mem/RehearsalWeightIgnoredWhileMoving": "true"})
    ignored.process(rgb, depth, CAM, planar_pose(0, 0, 0), 0)
    ignored.process(rgb, depth, CAM, planar_pose(0.02, 0, 0), 1)
    assert [n.weight for n in ignored.memory.nodes.values()] == [0, 0]
    off = Rtabmap({**params, "Mem/RehearsalSimilarity": "1"})
    off.process(rgb, depth, CAM, planar_pose(0, 0, 0), 0)
    r = off.process(rgb, depth, CAM, planar_pose(0.02, 0, 0), 1)
    assert "Memory/Rehearsal_sim/" not in r.statistics
    assert [n.weight for n in off.memory.nodes.values()] == [0, 0]


def test_transfer_takes_lowest_weight_then_oldest_never_nodes_linked_to_stm():
    mem = _chain(12, 3)  # WM 1..9, STM 10..12
    mem.nodes[2].weight = 5
    mem.nodes[4].weight = 1
    # 9 is linked to STM's oldest node (10): never transferred; weight 0 first, oldest first
    assert mem.transfer_candidates(set(), 0.0, 20) == [1, 3, 5, 6, 7, 8, 4, 2]
    assert mem.transfer_candidates({1, 5}, 0.0, 3) == [3, 6, 7]
    # sorting by weight then id (Mem/TransferSortingByWeightId) versus WM entry time: a node
    # retrieved back into WM re-enters last
    mem.transfer_to_ltm(3)
    assert mem.retrieve(3)
    assert mem.transfer_candidates(set(), 0.0, 3) == [1, 5, 6]
    assert mem.transfer_candidates(set(), 0.0, 3, sort_by_weight_id=True) == [1, 3, 5]


def test_transfer_spares_the_last_loop_closure_and_the_recent_part_of_wm():
    mem = _chain(30, 2)  # WM 1..28, STM 29..30
    mem.add_link(Link(20, 3, LinkType.GLOBAL_CLOSURE, np.eye(4), np.eye(6)))
    mem.nodes[3].weight = 4
    mem.closure_weights(mem.links[20][3])
    assert (mem.nodes[20].weight, mem.nodes[3].weight) == (4, 0)
    assert mem.last_loop_closure_id == 20
    # recent part: 20..28 (9 nodes) against RecentWmRatio · 28 = 14 → immunized
    out = mem.transfer_candidates(set(), 0.5, 40)
    assert out and max(out) < 20 and 20 not in out
    assert out[:3] == [1, 2, 3]
    # a ratio the recent part exceeds (9 nodes from 20 on > int(0.2 · 28) = 5): recent nodes
    # go too, lowest weight first, until fewer than 5 of them are left; 20 never goes
    for i in range(1, 20):
        mem.nodes[i].weight = 1
    out = mem.transfer_candidates(set(), 0.2, 40)
    assert out == [21, 22, 23, 24, 25, *range(1, 20)]


def test_memory_threshold_keeps_the_place_seen_longest(tmp_path):
    params = {**BASE, "Mem/STMSize": "3", "Rtabmap/MemoryThr": "6"}
    with SessionDatabase(tmp_path / "w.db") as db:
        slam = Rtabmap(params, database=db)
        stamp = 0
        ids = []
        for k in range(16):
            pose = planar_pose(0, 0, 0.26 * k)
            views = 4 if k == 2 else 1  # the robot stays a while at the third view
            for _ in range(views):
                r = slam.process(*frame(4, 4.0, 3.0, 0.26 * k), CAM, pose, stamp)
                stamp += 1
                if r.added:
                    ids.append(r.node_id)
        assert len(ids) == 16  # the repeats were merged into the third node, not kept
        dwelt = ids[2]
        assert slam.memory.nodes[dwelt].weight == 3
        assert all(slam.memory.nodes[i].weight == 0 for i in ids if i != dwelt)
        assert len(slam.memory.wm) <= 6
        # the oldest nodes went to LTM, the one seen longest stayed
        assert dwelt in slam.memory.wm
        assert {ids[0], ids[1], ids[3], ids[4]} <= slam.memory.ltm
        weights = {n.id: n.weight for n in db.nodes()}
        assert weights[dwelt] == 3


def test_nodes_rebuild_their_cloud_from_decimated_depth():
    rgb, depth = frame(3, 2.0, 3.0, 0.3)
    images = CloudImages.from_frame(depth, rgb, CAM, 4, 0.0, 5.0)
    assert images.nbytes < 20_000  # 320×240: the kept cloud was ~60 kB
    xyz, colors = images.cloud(0.0)
    ref_xyz, ref_colors = depth_cloud(depth, CAM, 4, 0.0, 5.0, rgb)
    assert xyz.shape == ref_xyz.shape
    np.testing.assert_allclose(xyz, ref_xyz, atol=1e-9)  # mm depth: stored without loss
    assert np.mean(np.abs(colors.astype(int) - ref_colors.astype(int))) < 8  # JPEG
    first = voxel_first_indices(ref_xyz, 0.02)
    np.testing.assert_allclose(images.cloud(0.02)[0], ref_xyz[first], atol=1e-9)
    slam = Rtabmap(BASE)
    r = slam.process(rgb, depth, CAM, planar_pose(1.0, 0.5, 0.2), 0,
                     features=FrameFeatures.empty())
    node = slam.memory.nodes[r.node_id]
    assert node.data is not None and isinstance(node.data.cloud, CloudImages)
    cloud, _ = slam.point_cloud(0.0)
    pose = slam.optimized_poses[r.node_id]
    local = images.cloud(0.02)[0]
    np.testing.assert_allclose(cloud[:5], local[:5] @ pose[:3, :3].T + pose[:3, 3], atol=1e-9)


def test_nodes_loaded_from_the_database_rebuild_their_cloud_from_the_stored_depth(tmp_path):
    poses = [planar_pose(0.0, 0.0, 0.0), planar_pose(0.3, 0.0, 0.4)]
    with SessionDatabase(tmp_path / "c.db") as db:
        slam = Rtabmap(BASE, database=db)
        for k, pose in enumerate(poses):
            slam.process(*frame(3, 2.0 + pose[0, 3], 3.0, 0.4 * k), CAM, pose, k)
        before = {i: n.data.cloud.cloud(0.02) for i, n in slam.memory.nodes.items()}
        db.close(slam)
    assert len(before) == 2 and all(xyz.shape[0] > 500 for xyz, _ in before.values())
    with SessionDatabase(tmp_path / "c.db") as db:
        again = Rtabmap(BASE, database=db)
        assert all(n.data is not None and n.data.cloud is None
                   for n in again.memory.nodes.values())
        for i, (xyz, rgb) in before.items():
            images = again._cloud_images(again.memory.nodes[i])
            assert images is not None
            after, after_rgb = images.cloud(0.02)
            np.testing.assert_allclose(after, xyz, atol=1e-9)
            # colours from the stored JPEG, compressed once more
            assert np.mean(np.abs(after_rgb.astype(int) - rgb.astype(int))) < 8
            assert again.memory.nodes[i].data.cloud is images  # kept from now on
