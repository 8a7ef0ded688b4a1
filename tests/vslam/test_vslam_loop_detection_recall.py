from eddiebot.vslam.loops import precision_recall_curve, recall_at_full_precision


def test_recall_at_full_precision_counts_right_hypotheses_until_the_first_wrong_one():
    # values sorted: 0.9 right, 0.8 near (ignored), 0.7 right, 0.6 wrong, 0.5 right
    values = [0.5, 0.9, 0.0, 0.7, 0.6, 0.8]
    verdicts = [1, 1, 0, 1, -1, 0]
    recall, thr = recall_at_full_precision(values, verdicts, n_positive=4)
    assert recall == 0.5 and thr == 0.7
    curve = precision_recall_curve(values, verdicts, n_positive=4)
    assert [t for t, _, _ in curve] == [0.9, 0.8, 0.7, 0.6, 0.5]  # 0.0 = no hypothesis
    assert curve[3] == (0.6, 2 / 3, 0.5)
    assert curve[4] == (0.5, 3 / 4, 0.75)


def test_ties_are_accepted_together_and_a_wrong_first_hypothesis_gives_zero():
    recall, thr = recall_at_full_precision([0.4, 0.4, 0.2], [1, -1, 1], n_positive=2)
    assert recall == 0.0 and thr == 1.0
    recall, _ = recall_at_full_precision([0.4, 0.4, 0.2], [1, 1, 1], n_positive=4)
    assert recall == 0.75


def test_near_places_at_the_top_are_not_errors():
    curve = precision_recall_curve([0.9, 0.8, 0.3], [0, 1, -1], n_positive=2)
    assert curve[0] == (0.9, 1.0, 0.0)
    assert recall_at_full_precision([0.9, 0.8, 0.3], [0, 1, -1], n_positive=2) == (0.5, 0.8)
