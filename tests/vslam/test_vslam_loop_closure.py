import numpy as np
from vslam_synthetic import box_scan, frame, kinect_camera, planar_pose

from eddiebot.vslam.bayes import VIRTUAL_PLACE_ID, BayesFilter, adjust_likelihood, tfidf_scores
from eddiebot.vslam.features import FeatureExtractor, FrameFeatures
from eddiebot.vslam.loops import AppearanceLoopDetector
from eddiebot.vslam.parameters import DEFAULT_PREDICTION_LC, RtabmapParameters
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.vocabulary import Vocabulary

CAM = kinect_camera(320, 240)
REPORT = {"RGBD/LinearUpdate": "0.05", "RGBD/ProximityBySpace": "false",
          "Reg/Force3DoF": "true", "Vis/MinInliers": "12"}


def _out_and_back(step=0.1, length=1.6):
    n = round(length / step)
    return [k * step for k in range(n + 1)] + [k * step for k in range(n - 1, -1, -1)]


def test_tfidf_and_likelihood_adjustment():
    inverted = {1: {10: 2, 11: 1}, 2: {10: 1}, 3: {12: 1}}
    totals = {10: 3, 11: 1, 12: 1}
    s = tfidf_scores({1: 1, 2: 1}, inverted, totals, 4, [10, 11, 12])
    assert s[10] > s[11] > 0 and s[12] == 0
    like = adjust_likelihood({10: 5.0, 11: 0.1, 12: 0.1, 13: 0.2})
    assert like[10] > 1.0 and like[11] == 1.0
    assert like[VIRTUAL_PLACE_ID] > 1.0
    assert adjust_likelihood({10: 0.0})[VIRTUAL_PLACE_ID] == 2.0


def test_bayes_filter_moves_mass_to_a_consistently_likely_place():
    lc = RtabmapParameters().prediction_lc()
    bayes = BayesFilter(lc, 0.9)
    chain = {1: {2: 1, 3: 2}, 2: {1: 1, 3: 1}, 3: {2: 1, 1: 2}}
    post = {}
    for _ in range(3):
        post = bayes.update({VIRTUAL_PLACE_ID: 1.0, 1: 1.0, 2: 8.0, 3: 1.0},
                            lambda i, d: chain[i])
    assert max(post, key=post.get) == 2
    assert 1.0 - post[VIRTUAL_PLACE_ID] > 0.5
    assert abs(sum(post.values()) - 1.0) < 1e-9
    assert DEFAULT_PREDICTION_LC.startswith("0.1 0.36")


def test_vocabulary_quantizes_repeats_to_same_words_and_new_ones_apart():
    rng = np.random.default_rng(0)
    vocab = Vocabulary(0.8, exact_max=64)  # small: exercises the LSH levels too
    base = rng.integers(0, 256, (300, 32), dtype=np.uint8)
    ids = vocab.quantize(base)
    assert len(set(ids.tolist())) == 300 and len(vocab) == 300
    vocab.add_references(ids)
    noisy = base.copy()
    flips = rng.integers(0, 32, 300)
    noisy[np.arange(300), flips] ^= 0x11  # 2 bits differ
    again = vocab.quantize(noisy, add_new=False)
    assert np.mean(again == ids) > 0.95
    other = rng.integers(0, 256, (50, 32), dtype=np.uint8)
    fresh = vocab.quantize(other)
    assert np.all(fresh > 300)
    vocab.remove_references(ids)
    assert vocab.active_words == 0


def test_rtabmap_detects_revisit_and_closes_loop():
    slam = Rtabmap(REPORT)
    xs = _out_and_back()
    loops = []
    for k, x in enumerate(xs):
        rgb, depth = frame(3, 2.0 + x, 3.0, 0.0)
        # odometry drifts 5 % in x and sideways
        odom = planar_pose(1.05 * x, 0.03 * x, 0.004 * k)
        r = slam.process(rgb, depth, CAM, odom, k * 1_000_000_000)
        loops.append(r.loop_closure_id)
    # on the way back (after STM), frames close loops with the outbound nodes
    back = loops[len(xs) // 2 + 5:]
    assert sum(1 for lc in back if lc) >= len(back) // 2
    poses, links = slam.graph()
    final = poses[max(poses)]
    # the corrected pose at the start is close to the first node (odometry drift removed)
    assert np.hypot(final[0, 3], final[1, 3]) < 0.05
    assert any(lk.type == 1 for lk in links)


def test_novel_place_is_not_a_loop():
    # default STM (10): the novel frames are only compared with the first room's frames
    det = AppearanceLoopDetector()
    for k in range(20):
        det.process(frame(4, 4.0, 3.0, 0.26 * k)[0])
    values = []
    for k in range(6):
        d = det.process(frame(5, 1.5 + 0.15 * k, 3.0, 1.2)[0])
        values.append(d.hypothesis_value)
        assert d.loop_id == 0
    assert max(values) < 0.11


def test_appearance_detector_finds_revisit():
    # a full turn in place, then the first views again (slightly rotated)
    det = AppearanceLoopDetector()
    ids = [det.process(frame(4, 4.0, 3.0, 0.26 * k)[0]).node_id for k in range(24)]
    found = [det.process(frame(4, 4.0, 3.0, 0.26 * k + 0.03)[0]) for k in (2, 3, 4)]
    assert [d.loop_id for d in found] == [ids[2], ids[3], ids[4]]
    assert min(d.hypothesis_value for d in found) >= 0.11


def test_geometric_verification_rejects_wrong_loop():
    # The revisit has the words of node 1 (same descriptors) but its keypoints are shuffled
    # across the image: appearance says "node 1", geometry cannot agree.
    # A low LoopThr lets the single revisit frame raise a hypothesis; the test is about
    # what happens after.
    slam = Rtabmap({**REPORT, "Mem/STMSize": "2", "Rtabmap/LoopThr": "0.05"})
    for k in range(5):
        slam.process(*frame(3, 2.0 + 0.3 * k, 3.0, 0.0), CAM, planar_pose(0.3 * k, 0, 0),
                     k * 1_000_000_000)
    rgb, depth = frame(3, 2.0, 3.0, 0.0)
    feats = FeatureExtractor(slam.params, max_features=1000, strategy=8).extract(rgb, depth, CAM)
    perm = np.random.default_rng(1).permutation(len(feats))
    shuffled = FrameFeatures(feats.uv[perm], feats.responses, feats.sizes, feats.angles,
                             feats.octaves, feats.descriptors, feats.points[perm])
    r = slam.process(rgb, depth, CAM, planar_pose(0.0, 0.0, 0.0), 5_000_000_000,
                     features=shuffled)
    assert r.hypothesis_id == 1 and r.hypothesis_value >= 0.05
    assert r.loop_closure_id == 0 and r.rejected_loop_id == 1
    assert "registration failed" in r.rejection_reason
    # the same frame with its true keypoints is accepted
    r2 = slam.process(rgb, depth, CAM, planar_pose(0.0, 0.0, 0.0), 6_000_000_000, features=feats)
    assert r2.loop_closure_id in (1, 2)


def test_optimize_max_error_rejects_closure_that_breaks_the_graph():
    # Odometry claims (with tiny covariance) the robot is 3 m away from where the image
    # says it is: the loop link cannot be satisfied and is removed.
    slam = Rtabmap({**REPORT, "Mem/STMSize": "2", "Rtabmap/LoopThr": "0.05"})
    cov = np.eye(6) * 1e-6
    for k in range(5):
        slam.process(*frame(3, 2.0 + 0.3 * k, 3.0, 0.0), CAM, planar_pose(0.3 * k, 0, 0),
                     k * 1_000_000_000, odom_covariance=cov)
    r = slam.process(*frame(3, 2.0, 3.0, 0.0), CAM, planar_pose(3.0, 0.0, 0.0),
                     5_000_000_000, odom_covariance=cov)
    assert r.loop_closure_id == 0
    assert r.rejected_loop_id == 1
    assert "OptimizeMaxError" in r.rejection_reason
    _, links = slam.graph()
    touching = [lk for lk in links if r.node_id in (lk.from_id, lk.to_id)]
    assert [lk.type for lk in touching] == [0]


def test_proximity_by_space_links_nearby_node():
    params = {**REPORT, "RGBD/ProximityBySpace": "true", "Mem/STMSize": "2",
              "Rtabmap/LoopThr": "1.1"}  # no global closures: only proximity can link
    slam = Rtabmap(params)
    xs = [0.0, 0.3, 0.6, 0.9, 1.2, 0.9, 0.6, 0.3, 0.05]
    got = []
    for k, x in enumerate(xs):
        r = slam.process(*frame(3, 2.0 + x, 3.0, 0.0), CAM, planar_pose(x, 0.02 * k, 0),
                         k * 1_000_000_000)
        got.append(r.proximity_id)
    assert any(got[5:])
    _, links = slam.graph()
    assert any(lk.type == 2 for lk in links)



def _proximity_run(extra, *, odom_y=0.02, scans=False):
    """Out and back along x in the box room; the return leg's odometry is off by `odom_y`
    per frame in y (drift). Returns the proximity ids and the core."""
    params = {**REPORT, "RGBD/ProximityBySpace": "true", "Mem/STMSize": "2",
              "Rtabmap/LoopThr": "1.1", **extra}  # no global closures: only proximity links
    slam = Rtabmap(params)
    xs = [0.0, 0.3, 0.6, 0.9, 1.2, 0.9, 0.6, 0.3, 0.05]
    got = []
    for k, x in enumerate(xs):
        scan = box_scan(2.0 + x, 3.0, 0.0) if scans else None
        r = slam.process(*frame(3, 2.0 + x, 3.0, 0.0), CAM, planar_pose(x, odom_y * k, 0),
                         k * 1_000_000_000, scan=scan)
        got.append(r.proximity_id)
    return got, slam


def test_proximity_candidates_are_within_the_local_radius():
    got, _ = _proximity_run({"RGBD/LocalRadius": "10"})
    assert any(got[5:])
    got, _ = _proximity_run({"RGBD/LocalRadius": "0.01"})  # nothing within 1 cm
    assert not any(got)


def test_proximity_candidates_are_within_the_graph_depth():
    # the return frames are 2 to 8 links from the outbound nodes that face them
    got, _ = _proximity_run({"RGBD/ProximityMaxGraphDepth": "1"})
    assert not any(got)
    got, _ = _proximity_run({"RGBD/ProximityMaxGraphDepth": "50"})
    assert any(got[5:])


def test_proximity_scan_pass_links_when_vision_cannot():
    # Vis/MinInliers beyond any frame's features: only the merged-scan ICP can link; odometry
    # drifts 0.03 m per frame sideways, the scans see the true poses
    extra = {"Vis/MinInliers": "5000", "RGBD/ProximityPathMaxNeighbors": "3"}
    got, slam = _proximity_run(extra, odom_y=0.03, scans=True)
    assert any(got[5:])
    _, links = slam.graph()
    prox = [lk for lk in links if lk.type == 2]
    assert prox
    for lk in prox:
        # the new node is (true) at the same y as the old one; the link says so within 3 cm
        # although odometry put them up to 0.24 m apart
        rel = lk.transform
        assert abs(rel[1, 3]) < 0.03
    # without the scan pass nothing links
    got, _ = _proximity_run({"Vis/MinInliers": "5000"}, odom_y=0.03, scans=True)
    assert not any(got)
