"""The samples figure's footage rows: longer banks never hold a judged sentence."""

import doctest

import pytest

from lipsync.bench import samples as B


def test_a_longer_bank_adds_the_tuning_sentences_in_order_and_never_a_judged_one():
    bank = [f"b{i}" for i in range(10)]
    held = [f"h{i}" for i in range(30)]
    judged = set(held[:B.TUNED_FROM])
    for count in (10, 12, 16, 22):
        got = B.footage_clips(bank, held, count)
        assert len(got) == len(set(got)) == count
        assert got[:10] == bank
        assert got[10:] == held[B.TUNED_FROM:B.TUNED_FROM + count - 10]
        assert not judged & set(got)


def test_asking_more_sentences_than_lie_outside_the_judged_ones_is_an_error():
    held = [f"h{i}" for i in range(30)]
    assert len(B.footage_clips(["b"], held, 13)) == 13          # 1 + the 12 tuning sentences
    with pytest.raises(ValueError, match="only 13 are outside"):
        B.footage_clips(["b"], held, 14)


@pytest.mark.parametrize("name", ["lipsync.bench.samples", "lipsync.samples.lipmodel", "lipsync.selection.select",
                                  "lipsync.speech.features"])
def test_the_examples_of_the_target_modules_run(name):
    import importlib

    mod = importlib.import_module(name)
    assert doctest.testmod(mod, optionflags=doctest.ELLIPSIS).failed == 0
