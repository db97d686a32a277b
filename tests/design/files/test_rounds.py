"""rounds.npz (design.files.rounds): a round state is stored and read back whole; a file written before the rounds
recorded their step and the best design's curves reads as step 1 without them; a newer layout is refused."""
from dataclasses import fields

import numpy as np
import pytest

from design.errors import DesignError
from design.files.rounds import ROUNDS, ROUNDS_FORMAT, RoundFile
from design.inverse.defect import RoundState


def _state(**changes):
    values = dict(round=2, start=80, end=100, bias_mm3=np.array([0.0, 0.5, -0.25]), x_start=np.linspace(0, 1, 6),
                  best_x=np.linspace(1, 0, 6), best_fit=0.0123, best_pieces=1, fits=np.array([0.02, 0.0123]),
                  status="max_iter", step=0.25, best_grid_mm3=np.array([0.0, 3.0, 5.0]),
                  best_print_mm3=np.array([0.0, 2.5, 5.25]))
    values.update(changes)
    return RoundState(**values)


def test_a_round_state_is_read_back_whole(tmp_path):
    store = RoundFile(tmp_path / ROUNDS)
    assert store.load() is None
    state = _state()
    store.save(state)
    loaded = store.load()
    for f in fields(RoundState):
        np.testing.assert_array_equal(getattr(loaded, f.name), getattr(state, f.name))
    assert isinstance(loaded.step, float) and loaded.step == 0.25


def test_a_state_without_the_step_reads_as_a_full_step_without_the_best_curves(tmp_path):
    state = _state()
    arrays = {f.name: np.asarray(getattr(state, f.name)) for f in fields(RoundState)
              if f.name not in ("step", "best_grid_mm3", "best_print_mm3")}
    np.savez(tmp_path / ROUNDS, format=np.array(ROUNDS_FORMAT), **arrays)
    loaded = RoundFile(tmp_path / ROUNDS).load()
    assert loaded.step == 1.0 and loaded.best_grid_mm3.size == 0 and loaded.best_print_mm3.size == 0
    np.testing.assert_array_equal(loaded.bias_mm3, state.bias_mm3)
    assert loaded.round == 2 and loaded.best_fit == 0.0123


def test_a_state_missing_a_required_field_or_of_another_layout_is_refused(tmp_path):
    state = _state()
    arrays = {f.name: np.asarray(getattr(state, f.name)) for f in fields(RoundState) if f.name != "bias_mm3"}
    np.savez(tmp_path / ROUNDS, format=np.array(ROUNDS_FORMAT), **arrays)
    with pytest.raises(DesignError, match="not a readable round state"):
        RoundFile(tmp_path / ROUNDS).load()
    np.savez(tmp_path / ROUNDS, format=np.array(ROUNDS_FORMAT + 1), **arrays)
    with pytest.raises(DesignError, match="is not the layout this version reads"):
        RoundFile(tmp_path / ROUNDS).load()
