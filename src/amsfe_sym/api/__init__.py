"""The public Python API: a robot's library, a scenario, a simulation, a log in arrays and
an estimator over it, each one call (docs/api.md).  Every name here is also the package's
(``import amsfe_sym as am; am.simulate()``).

Everything here composes the toolkit's own parts (the ones the ``amsfe`` commands use), so
a number from the API is the command's number: :meth:`Estimator.run` on a log read with
:func:`read_log` gives ``amsfe estimate``'s estimates, :func:`simulate` ``amsfe simulate``'s
run.  Nothing is written to disk but the robot's generated library (cached by content).

Units: SI throughout; angles [rad], rates [rad/s], torques [N m], times [s], pixels [px].
The state is the paper's eq. (2), ``x = [q, qd, qm, qmd, theta]`` (``N = 4 n + p``): link
angles, link rates, motor angles, motor rates, the unknown parameters.

The low-level API (what these functions are made of, for a reader who needs one part):
:func:`amsfe_sym.codegen.library_for` (a scenario's loaded library),
:class:`amsfe_sym.runtime.library.ModelLibrary` (its functions, ``lib.function(name)``),
:func:`amsfe_sym.sim.loop.run` (the closed loop, a :class:`~amsfe_sym.sim.result.RunResult`),
:func:`amsfe_sym.sim.builders.build_estimator` (an estimator of a scenario),
:class:`amsfe_sym.runtime.models.CompiledTransition` (the compiled transition and its
noise), :func:`amsfe_sym.sim.effort.effort_estimator` (an estimator for a log's kind of
effort), :func:`amsfe_sym.logs.replay.estimate_log` (an estimator over a read log).

Modules: ``scenarios`` (:func:`generate`, :func:`load_scenario`, :func:`simulate`),
``recordings`` (:class:`LogArrays`, :func:`read_log`), ``estimator`` (:class:`Estimator`),
``model`` (:class:`Model`: a scenario's transition, its jacobian and noise, the camera map).
May import every room but the command line (it composes the applications' parts).

The public names are listed once, in the package root's ``__all__`` (written out there, so
that ``import amsfe_sym`` imports nothing); here each is imported ``as`` itself, the
explicit re-export of PEP 484 that mypy (``--no-implicit-reexport``) and ruff read.
"""

from amsfe_sym.api.estimator import EstimateArrays as EstimateArrays
from amsfe_sym.api.estimator import Estimator as Estimator
from amsfe_sym.api.estimator import StepResult as StepResult
from amsfe_sym.api.model import Model as Model
from amsfe_sym.api.recordings import LogArrays as LogArrays
from amsfe_sym.api.recordings import read_log as read_log
from amsfe_sym.api.scenarios import Robot as Robot
from amsfe_sym.api.scenarios import SimResult as SimResult
from amsfe_sym.api.scenarios import generate as generate
from amsfe_sym.api.scenarios import load_scenario as load_scenario
from amsfe_sym.api.scenarios import simulate as simulate
