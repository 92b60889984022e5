"""The command line's options objects (apps/arguments.options_from_args): each field of
``amsfe live``'s :class:`PairOptions` and ``amsfe bench``'s :class:`BenchOptions` is the
option of its name, or its conversion, as the parser reads a real argv; the command table
names every command once."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any

import pytest

from amsfe_sym.apps.arguments import options_from_args
from amsfe_sym.apps.bench.logs import LogCase
from amsfe_sym.apps.bench.report import BenchOptions
from amsfe_sym.apps.cli import _commands, get_argument_parser, main
from amsfe_sym.ros.pair import PairOptions


def _taken(monkeypatch: pytest.MonkeyPatch, module: str, name: str, argv: list[str]) -> Any:
    """The options object ``main(argv)`` hands to ``module.name`` (the command's runner,
    replaced so that no process starts and nothing is timed)."""
    seen: list[Any] = []
    monkeypatch.setattr(f"{module}.{name}", lambda opts: seen.append(opts) or 0)
    assert main(argv) == 0
    (opts,) = seen
    return opts


def test_live_options_are_its_arguments(monkeypatch: pytest.MonkeyPatch) -> None:
    argv = ["live", "ur5-control", "--lockstep", "--duration", "1.5", "--seed", "7"]
    argv += ["--rate", "0.5", "--impl", "python", "--topic-spec", "spec.toml"]
    argv += ["--encoder-timeout", "0.2", "--command-timeout", "3"]
    argv += ["--ros-args", "-p", "qos.depth:=10"]
    got = _taken(monkeypatch, "amsfe_sym.ros.pair", "run_pair", argv)
    assert got == PairOptions(
        scenario="ur5-control",
        controller=None,  # --controller "" (the default): the scenario's
        lockstep=True,
        duration=1.5,
        seed=7,
        rate=0.5,
        impl="python",
        record=None,
        topic_spec="spec.toml",
        ros_args=("-p", "qos.depth:=10"),
        encoder_timeout=0.2,
        command_timeout=3.0,
    )
    default = _taken(monkeypatch, "amsfe_sym.ros.pair", "run_pair", ["live", "--controller", "x"])
    assert default == PairOptions(controller="x")


def test_bench_options_are_its_arguments(monkeypatch: pytest.MonkeyPatch) -> None:
    argv = ["bench", "panda", "--repeat", "300", "--rounds", "3", "--skip", "calls", "loop"]
    argv += ["--duration", "0.5", "--scenario", "paper-sim", "--estimators", "ekf", "replay"]
    argv += ["--compare-cflags=-O1, -O2 -march=native,", "--compile-repeat", "2"]
    argv += ["--joints", "2-4", "--loop-duration", "3", "--loop-scenarios", "a,b"]
    argv += ["--no-panda", "--scaling-loop-duration", "1", "--logs", "paper-sim:2"]
    got = _taken(monkeypatch, "amsfe_sym.apps.bench", "run_bench", argv)
    assert got == BenchOptions(
        robot="panda",
        out=None,
        repeat=300,
        rounds=3,
        json=None,
        skip=("calls", "loop"),
        duration=0.5,
        scenario="paper-sim",
        estimators=("ekf", "replay"),
        compare_cflags=("-O1", "-O2 -march=native"),
        compile_repeat=2,
        joints=(2, 3, 4),
        loop_duration=3.0,
        loop_scenarios=("a", "b"),
        scaling_panda=False,
        scaling_loop_duration=1.0,
        logs=(LogCase("paper-sim", 2.0),),
    )
    # no options: the dataclass's own defaults, but for the robot as the parser names it
    default = _taken(monkeypatch, "amsfe_sym.apps.bench", "run_bench", ["bench"])
    assert default == BenchOptions()


def test_a_field_without_its_option_is_an_error_not_a_default() -> None:
    @dataclass(frozen=True)
    class Opts:
        rate: float = 1.0
        impl: str = "auto"

    args = argparse.Namespace(rate=2.0)
    with pytest.raises(AttributeError, match="impl"):
        options_from_args(Opts, args)
    assert options_from_args(Opts, args, impl="c") == Opts(2.0, "c")


def test_every_command_of_the_table_parses_and_has_its_help(capsys) -> None:
    """Each row of the command table is a subcommand whose ``-h`` exits 0 with its usage,
    in the table's order in ``amsfe -h``."""
    names = list(_commands())
    assert names[:3] == ["generate", "check", "simulate"] and len(names) == len(set(names))
    for name in names:
        assert main([name, "-h"]) == 0
        assert capsys.readouterr().out.startswith(f"usage: amsfe {name} ")
    parser = get_argument_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert [a.dest for a in sub._choices_actions] == names
    assert [a.help for a in sub._choices_actions] == [c.help for c in _commands().values()]
