"""``--worker-timeout`` is checked by ``check_number`` like every other number option: same message, same
rule (> 0, finite), and still refused without ``--scheduler``. With no upper bound the message asks for
a finite number, never for one "<= inf" (review s10, finding 8)."""

from __future__ import annotations

import math

import pytest

from arboretum_library.checks import check_number
from arboretum_library.errors import InputError
from arboretum_server.batch.build import BuildOptions

SCHEDULER = "tcp://127.0.0.1:8786"


@pytest.mark.parametrize("bad", [0, 0.0, -1.5, math.inf, -math.inf, math.nan])
def test_a_bad_worker_timeout_has_the_message_of_every_number_option(bad):
    with pytest.raises(InputError) as want:
        check_number(bad, "--worker-timeout", 0.0, math.inf, lo_open=True)
    with pytest.raises(InputError) as got:
        BuildOptions(scheduler=SCHEDULER, worker_timeout=bad)
    assert str(got.value) == str(want.value) == f"--worker-timeout must be a number > 0 and finite, got {bad}"


@pytest.mark.parametrize("good", [None, 1e-3, 1.5, 86400.0])
def test_a_positive_finite_worker_timeout_or_none_is_taken(good):
    assert BuildOptions(scheduler=SCHEDULER, worker_timeout=good).worker_timeout == good


def test_without_a_scheduler_a_worker_timeout_is_refused_and_a_bad_number_is_named_first():
    with pytest.raises(InputError, match=r"^--worker-timeout applies only with --scheduler \(a local cluster"):
        BuildOptions(worker_timeout=5.0)
    with pytest.raises(InputError, match=r"^--worker-timeout must be a number > 0 and finite, got -1"):
        BuildOptions(worker_timeout=-1)


def test_the_cli_prints_the_same_message_and_exits_2(tmp_path, capsys):
    from arboretum_library.cli import main

    code = main(["library", "build", str(tmp_path), "--library", str(tmp_path / "lib"),
                 "--scheduler", SCHEDULER, "--worker-timeout", "-2"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--worker-timeout must be a number > 0 and finite, got -2.0" in err[0]
    assert not (tmp_path / "lib").exists()


@pytest.mark.parametrize("args, message", [
    ((math.inf, "--step", 0.0, math.inf, True), "--step must be a number > 0 and finite, got inf"),
    ((-1.0, "--x", 0.0, math.inf, False), "--x must be a number >= 0 and finite, got -1.0"),
    ((30.0, "--density", 0.0, 20.0, True), "--density must be a number > 0 and <= 20, got 30.0"),
    ((math.nan, "--noise", 0.0, 1.0, False), "--noise must be a number >= 0 and <= 1, got nan"),
])
def test_check_number_never_asks_for_a_number_below_infinity(args, message):
    value, what, lo, hi, lo_open = args
    with pytest.raises(InputError) as info:
        check_number(value, what, lo, hi, lo_open=lo_open)
    assert str(info.value) == message
