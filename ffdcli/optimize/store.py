"""The evaluations of an optimisation run on disk: one folder each, the cache and ``--resume``.

Each evaluation lives in ``<folder>/evals/<NNNN>/`` (the deformed mesh, the solver's configs and logs)
with ``result.json`` written whole or not at all after each stage (the flow, then the adjoints), so
that Ctrl-C or SIGTERM loses nothing that finished. An evaluation is found again by its key: a hash
of the full design vector (its float64 bytes) and of the run's inputs (the mesh's content, the
solver's configuration, the design file without the optimiser's own run settings): the same design
of the same problem, never another's. A design within :data:`SAME_DESIGN` of a finished evaluation's
(each variable, in its own units) is that evaluation: a resumed run replays its optimiser's steps,
whose last digits may differ from the first run's (another version's arithmetic), and a design moved
by 1e-9 of a chord or a degree is not one a solver can tell from it.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_write, written_as

#: Largest difference of any variable (in its own units) between a design and a finished evaluation's
#: for the evaluation to answer for it.
SAME_DESIGN = 1e-9


@dataclass(frozen=True, eq=False)
class Evaluation:
    """One design evaluated (or its failure).

    values : (n_vars,) the full design vector; functions : {name: value} from the solver (empty when
    failed); gradients : {name: (n_vars,) dJ/dv} (empty until the adjoints ran); constraints : (C,)
    the geometric constraints; failed : the reason, None when it worked; log : the failing run's log;
    seconds : {"solver", "ffd", "optimizer"} (the optimiser's time before it asked for this design; absent
    in a result written before it was counted); solves : {"flow", "adjoint"} run for it."""

    index: int
    key: str
    values: np.ndarray
    folder: Path
    functions: dict = field(default_factory=dict)
    gradients: dict = field(default_factory=dict)
    constraints: np.ndarray = field(default_factory=lambda: np.zeros(0))
    failed: str | None = None
    log: str | None = None
    seconds: dict = field(default_factory=lambda: {"solver": 0.0, "ffd": 0.0, "optimizer": 0.0})
    solves: dict = field(default_factory=lambda: {"flow": 0, "adjoint": 0})
    iteration: int = 0

    def with_(self, **kw) -> Evaluation:
        return replace(self, **kw)

    def to_json(self) -> dict:
        """What ``result.json`` holds (floats written by repr: they read back bit for bit)."""
        return {"index": self.index, "key": self.key, "values": [float(v) for v in self.values],
                "functions": {k: float(v) for k, v in self.functions.items()},
                "gradients": {k: [float(x) for x in g] for k, g in self.gradients.items()},
                "constraints": [float(c) for c in self.constraints], "failed": self.failed, "log": self.log,
                "seconds": self.seconds, "solves": self.solves, "iteration": self.iteration}

    @classmethod
    def from_json(cls, data: dict, folder: Path) -> Evaluation:
        return cls(index=int(data["index"]), key=data["key"], values=np.array(data["values"], dtype=float),
                   folder=folder, functions=dict(data["functions"]),
                   gradients={k: np.array(g, dtype=float) for k, g in data["gradients"].items()},
                   constraints=np.array(data["constraints"], dtype=float), failed=data["failed"], log=data["log"],
                   seconds=dict(data["seconds"]), solves=dict(data["solves"]), iteration=int(data["iteration"]))


def file_hash(path: Path) -> str:
    """sha256 of a file's bytes (read by blocks)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


#: Keys of ``optimize:`` that steer the optimiser but do not change what an evaluation computes.
RUN_KEYS = ("iterations", "tolerance", "max_failures", "method", "line_search", "step", "scale", "folder",
            "feasibility", "functions", "objective", "variables", "warm_start", "screen",
            "concurrent_adjoints")


def inputs_hash(mesh: Path, solver_state: str, data: dict, names: list[str]) -> str:
    """The hash of what an evaluation's result depends on besides the design vector: the mesh's bytes,
    the solver's configuration, the design file's settings (box, volume, constraints; the changes'
    kinds through the variable ``names``, their values are the vector) and the variable names."""
    opt = {k: v for k, v in (data.get("optimize") or {}).items() if k not in RUN_KEYS}
    rest = {k: v for k, v in data.items() if k not in ("optimize", "changes", "output", "bounds")}
    text = json.dumps({"mesh": file_hash(mesh), "solver": solver_state, "design": rest, "optimize": opt,
                       "names": names}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


class EvaluationStore:
    """The evaluations of a run folder: ``find`` by design vector, ``new`` folder, ``save`` a result.

    ``resume``: the finished evaluations of an earlier run with the same inputs are read back; without
    it, a folder that already holds evaluations is refused (InputError), never silently mixed. ``accept``:
    other hashes of the same inputs (an earlier version's, :meth:`Solver.legacy_states`) whose evaluations
    are reused too, and their ``result.json`` rewritten with this hash and key (whole, as :meth:`save`
    writes), so that the run no longer depends on the earlier form (``migrated`` counts them)."""

    def __init__(self, folder: Path, inputs: str, *, resume: bool, accept: tuple[str, ...] = ()):
        self.folder = Path(folder)
        self.root = self.folder / "evals"
        self.inputs = inputs
        self.by_key: dict[str, Evaluation] = {}
        self.other_inputs = 0                           # finished evaluations of other inputs: not reused
        self.migrated = 0                               # ... of an accepted earlier hash: rewritten with this one
        self.next_index = 1
        existing = sorted(self.root.glob("*/result.json")) if self.root.is_dir() else []
        if existing and not resume:
            raise InputError(f"holds the evaluations of an earlier run ({len(existing)}); continue it with "
                             "--resume, or choose another optimize.folder", path=self.folder, key="optimize.folder")
        for path in existing:
            try:
                data = json.loads(path.read_text())
            except (OSError, ValueError):
                continue                                    # a result never finished: run again
            if data.get("inputs") != inputs and data.get("inputs") not in accept:
                self.other_inputs += 1
                continue
            ev = Evaluation.from_json(data, path.parent)
            if data["inputs"] != inputs:                # an earlier version's hash: moved to this one's
                ev = self.save(ev.with_(key=self.key(ev.values)))
                self.migrated += 1
            self.by_key[ev.key] = ev
        if self.root.is_dir():
            numbers = [int(p.name) for p in self.root.iterdir() if p.name.isdigit()]
            self.next_index = max(numbers, default=0) + 1
        self.reused = len(self.by_key)

    def key(self, values: np.ndarray) -> str:
        h = hashlib.sha256(self.inputs.encode())
        h.update(np.ascontiguousarray(values, dtype=np.float64).tobytes())
        return h.hexdigest()[:24]

    def find(self, values: np.ndarray) -> Evaluation | None:
        """The evaluation of ``values`` (n_vars,): its own, else the nearest within :data:`SAME_DESIGN`."""
        ev = self.by_key.get(self.key(values))
        if ev is not None or not self.by_key:
            return ev
        values = np.asarray(values, dtype=float)
        near = [e for e in self.by_key.values() if e.values.shape == values.shape]
        if not near:
            return None
        gap = np.abs(np.stack([e.values for e in near]) - values).max(axis=1)
        i = int(np.argmin(gap))
        return near[i] if gap[i] <= SAME_DESIGN else None

    def new(self, values: np.ndarray, iteration: int) -> Evaluation:
        """A fresh evaluation with its own (empty) folder."""
        index = self.next_index
        self.next_index += 1
        folder = self.root / f"{index:04d}"
        with written_as(folder, "an evaluation's folder", self._kept()):
            folder.mkdir(parents=True, exist_ok=True)
        return Evaluation(index=index, key=self.key(values), values=np.array(values, dtype=float), folder=folder,
                          iteration=iteration)

    def save(self, ev: Evaluation) -> Evaluation:
        """Write ``result.json`` of ``ev`` whole (atomic) and keep it in the cache."""
        data = {**ev.to_json(), "inputs": self.inputs}
        path = ev.folder / "result.json"
        with written_as(path, "an evaluation's result", self._kept()), atomic_write(path, "w") as fh:
            fh.write(json.dumps(data, indent=1))
        self.by_key[ev.key] = ev
        return ev

    def _kept(self) -> str:
        return f"the finished evaluations are kept in {self.folder} (continue with --resume)"

    def all(self) -> list[Evaluation]:
        """Every evaluation known, in index order."""
        return sorted(self.by_key.values(), key=lambda e: e.index)
