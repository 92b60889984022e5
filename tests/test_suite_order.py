"""The order the suite hands its tests out in (tests/conftest.py's ``heavy_first``,
docs/how-to/tests.md): the longest tests start first, on alternate workers, as xdist's own
scheduler (``--dist load``, what ``pytest -n 2`` uses) hands them out."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.conftest import HEAVY_FIRST, heavy_first

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class _Item:
    nodeid: str


class _Options:
    """The options of ``pytest -n WORKERS`` xdist's scheduler reads."""

    def __init__(self, workers: int) -> None:
        self._values = {"tx": [f"{workers}*popen"], "maxschedchunk": None}

    def getvalue(self, name: str) -> object:
        return self._values[name]

    getoption = getvalue


@dataclass(frozen=True)
class _Gateway:
    id: str


class _Worker:
    """What xdist's scheduler calls on a worker: the indices of the tests it is sent."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.gateway = _Gateway(name)
        self.sent: list[int] = []

    def send_runtest_some(self, indices: list[int]) -> None:
        self.sent += indices

    def shutdown(self) -> None:
        pass


def test_every_heavy_test_exists() -> None:
    """A renamed test or page left in ``HEAVY_FIRST`` would silently lose its place."""
    missing = []
    for nodeid in HEAVY_FIRST:
        file, name = nodeid.split("::")
        func, _, param = name.partition("[")
        text = (ROOT / file).read_text() if (ROOT / file).is_file() else ""
        page = param[:-1] if param.startswith("docs/") else ""
        if not re.search(rf"^def {func}\(", text, re.M) or (page and not (ROOT / page).is_file()):
            missing.append(nodeid)
    assert not missing, missing


@pytest.mark.parametrize("workers", [2, 3])
def test_xdist_starts_the_heavy_tests_first_on_alternate_workers(workers: int) -> None:
    """xdist's LoadScheduling, given the order ``heavy_first`` makes of a suite's worth of
    tests, sends the i-th heavy test to worker i mod ``workers``, each worker's heavy tests
    the first it runs, the costliest first; no test lost or sent twice."""
    from xdist.scheduler import LoadScheduling

    items = [_Item(f"tests/test_x{i // 40}.py::test_{i}") for i in range(1500)]
    items[700:700] = [_Item(n) for n in reversed(HEAVY_FIRST)]  # anywhere, any order
    order = [it.nodeid for it in heavy_first(items, workers)]  # type: ignore[arg-type]
    assert sorted(order) == sorted(it.nodeid for it in items)
    sched = LoadScheduling(_Options(workers))  # type: ignore[arg-type]
    nodes = [_Worker(f"gw{w}") for w in range(workers)]
    for node in nodes:
        sched.add_node(node)  # type: ignore[arg-type]
        sched.add_node_collection(node, order)  # type: ignore[arg-type]
    sched.schedule()
    for w, node in enumerate(nodes):
        mine = list(HEAVY_FIRST[w::workers])
        assert [order[i] for i in node.sent[: len(mine)]] == mine, node.name
