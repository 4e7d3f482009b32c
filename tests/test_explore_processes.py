"""Exploring robots as processes: each a ``gmmap robot --explore`` talking to its peers over
Zenoh, the simulator moving them in lockstep (`gmmap.eval.explore.processes`)."""

from __future__ import annotations

import numpy as np
import pytest
from test_explore import assert_in_different_rooms, config, saved, two_rooms

from gmmap.errors import DecodeError
from gmmap.eval.explore.processes import ProcessTeam, run_processes
from gmmap.fleet.wire.explore import (
    Step,
    Tick,
    decode_claim,
    decode_step,
    decode_tick,
    encode_claim,
    encode_json,
)
from gmmap.mapping.explore import Claim


def test_claims_ticks_and_steps_round_trip_and_garbage_is_a_typed_error():
    claim = decode_claim(encode_claim(Claim(np.array([1.5, -2.0]), None)))
    assert np.allclose(claim.position, [1.5, -2.0]) and claim.goal is None
    claim = decode_claim(encode_claim(Claim(np.zeros(2), np.array([3.0, 4.0]))))
    assert np.allclose(claim.goal, [3.0, 4.0])
    tick = Tick(1.5, {"a": [0.0, 1.0, 0.5]}, {"a": 3}, decide=False)
    assert decode_tick(encode_json(tick)) == tick
    step = Step([0.6, 0.8], "exploring", 4, 1200)
    assert decode_step(encode_json(step)) == step
    nan = encode_claim(Claim(np.array([np.nan, 0.0]), None))
    for bad in (b"", b"short", nan):
        with pytest.raises(DecodeError):
            decode_claim(bad)
    for bad in (b"", b"{}", b"[1, 2]", b"\xff"):
        with pytest.raises(DecodeError):
            decode_tick(bad)


def test_robots_as_processes_explore_two_rooms_and_end_in_different_rooms(tmp_path):
    r = run_processes(config(saved(two_rooms(), tmp_path), 2))
    assert_in_different_rooms(r)
    assert all(b > 1000 for b in r.bytes_per_robot)  # submaps, horizons and claims sent


def test_a_robot_process_that_fails_ends_the_run_with_an_error(tmp_path):
    team = ProcessTeam(config(saved(two_rooms(), tmp_path), 2))
    (tmp_path / "two-rooms.json").unlink()  # the simulator has loaded it; the robots cannot
    with pytest.raises(RuntimeError, match="robot process"):
        team.run()
