"""The one ``RESULTS`` enumeration: it extends optimistix's, every item has a word for
files, the words read back, and the integer codes earlier versions stored still map."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import gearjax as gj
from gearjax._engine import results as R

# the words results files and JSON have used since version 1 (interface.md)
FILE_WORDS = {"converged", "max_steps", "nonfinite", "not_periodic", "solver_failed",
              "reached_end", "max_points", "step_too_small", "closed_loop", "detour",
              "runaway"}


def test_extends_optimistix_and_promotes_its_results():
    assert issubclass(gj.RESULTS, optx.RESULTS)
    for name in ("successful", "nonlinear_max_steps_reached", "nonfinite"):
        item = gj.RESULTS.promote(getattr(optx.RESULTS, name))
        assert bool(item == getattr(gj.RESULTS, name))


def test_every_item_has_a_message_and_a_word_that_reads_back():
    names = R._NAMES
    assert len(names) == len(gj.RESULTS)  # the list of names misses no item
    words = {}
    for name in names:
        item = getattr(gj.RESULTS, name)
        assert name == "successful" or gj.RESULTS[item]
        word = gj.result_word(item)
        words[name] = word
        back = gj.result_from_word(word, time_domain=name == "max_steps_reached")
        assert bool(back == item), name
    assert FILE_WORDS <= set(words.values())
    assert words["successful"] == "converged"
    assert words["nonlinear_max_steps_reached"] == words["max_steps_reached"] == "max_steps"


def test_batched_items_give_arrays_of_words():
    codes = jax.vmap(jax.vmap(lambda x: gj.RESULTS.where(
        x > 0, gj.RESULTS.successful, gj.RESULTS.where(x < 0, gj.RESULTS.nonfinite,
                                                       gj.RESULTS.not_periodic))))(
        jnp.array([[1.0, -1.0], [0.0, 2.0]]))
    np.testing.assert_array_equal(gj.result_word(codes),
                                  [["converged", "nonfinite"], ["not_periodic", "converged"]])


def test_words_and_codes_of_earlier_versions():
    assert bool(gj.result_from_word("no converged start at 3288.1 Hz (max_steps)")
                == gj.RESULTS.no_converged_start)
    with pytest.raises(ValueError, match="unknown result 'periodic-ish'"):
        gj.result_from_word("periodic-ish")
    np.testing.assert_array_equal(R.legacy_words(np.array([0, 1, 2]), "hb"),
                                  ["converged", "max_steps", "nonfinite"])
    np.testing.assert_array_equal(R.legacy_words(np.array([1, 3]), "time_domain"),
                                  ["not_periodic", "solver_failed"])
    words = np.array(["converged", "max_steps"])
    np.testing.assert_array_equal(R.legacy_words(words, "hb"), words)
