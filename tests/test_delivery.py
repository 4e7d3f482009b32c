"""What counts as lost on links that come and go (`gmmap.eval.delivery`)."""

import numpy as np

from gmmap.eval.delivery import lasting, links_up, reachable


def test_a_submap_reaches_the_robots_a_chain_of_later_meetings_leads_to() -> None:
    # 0 meets 1 at frame 1 only, 1 meets 2 at frame 3 only; at frame 5 both links are up.
    meetings = {(0, 1): {1, 5}, (1, 2): {3, 5}}
    linked = links_up(lambda i, j, k: k in meetings[(i, j)], list(meetings), 3, 6)
    assert linked.shape == (6, 3, 3) and linked[1, 1, 0] and not linked[2, 0, 1]
    assert reachable(linked, 0, 0) == {1, 2}  # 1 at frame 1, which hands it on at frame 3
    assert reachable(linked, 2, 0) == {1, 0}  # 1 at frame 3; 0 and 1 meet again at frame 5
    assert reachable(linked, 2, 4) == {0, 1}  # both hops within frame 5
    linked[5] = False
    assert reachable(linked, 2, 2) == {1}  # 0 met 1 before 1 held it
    assert reachable(linked, 0, 4) == set()  # after its last meeting
    assert reachable(linked, 0, 99) == set()  # after the last frame the links stay as they end


def test_links_stay_as_they_ended_after_the_last_frame() -> None:
    linked = links_up(lambda i, j, k: k == 2, [(0, 1)], 2, 3)
    assert reachable(linked, 0, 7) == {1}
    assert not np.any(linked[:2])


def test_only_lasting_contacts_count_when_asked() -> None:
    up = np.zeros((10, 3, 3), dtype=bool)
    up[1, 0, 1] = up[1, 1, 0] = True  # one frame: brief
    up[3:6, 1, 2] = up[3:6, 2, 1] = True  # three frames
    up[8:, 0, 2] = up[8:, 2, 0] = True  # as the links end: lasting
    kept = lasting(up, 3)
    assert not kept[:, 0, 1].any()
    assert kept[3:6, 1, 2].all() and kept[3:6, 2, 1].all() and kept[:, 1, 2].sum() == 3
    assert kept[8:, 0, 2].all()
    assert reachable(up, 0, 0) == {1, 2}
    assert reachable(kept, 0, 0) == {2}  # the brief meeting with 1 is no chance


def test_a_robot_in_between_hands_on_only_what_it_held_for_a_hold_in_one_contact() -> None:
    up = np.zeros((12, 4, 4), dtype=bool)
    up[5:8, 0, 2] = up[5:8, 2, 0] = True  # 0 hands its own on at once
    up[4:8, 2, 3] = up[4:8, 3, 2] = True  # four frames, two of them after 2 got it
    up[10:, 1, 3] = up[10:, 3, 1] = True  # as the links end: time for any hop
    assert reachable(up, 0, 0) == {1, 2, 3}
    assert reachable(up, 0, 0, hold=3) == {2}  # 2 met 3 too soon after it got it
    assert reachable(up, 0, 8, hold=3) == set()  # after 0 and 2 parted
    assert reachable(up, 3, 8, hold=3) == {1}  # the links as they end carry 3's own
    up[8, 2, 3] = up[8, 3, 2] = True
    assert reachable(up, 0, 0, hold=3) == {1, 2, 3}  # 2 held it through frames 6 to 8
