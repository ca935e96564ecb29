"""Every failure the solver reports, as typed exceptions that carry their facts as fields.

Callers decide by type and fields, never by the message text:

- :class:`InputError` (exit code 2): the user's input is wrong. :class:`ConfigError` for a
  scene (``key``, ``value``, ``allowed``, ``source``), :class:`UsageError` for the command
  line and the results directory (:class:`OutputDirectoryError` for one a run may not write to: ``directory``,
  ``problem``, ``existing``; :class:`ResultsError` for a damaged one: ``path``, ``reason``),
  :class:`ToleranceError` for a tolerance out of reach
  (``tolerance``, ``estimate``, ``dofs``, ``limit``, ``predicted``), :class:`RigidMotionError` for supports that
  leave a rigid motion free (``motions``).
- :class:`SolveFailure` (exit code 1): a run stopped. It knows the ``step`` and time ``t``
  (filled in by the stepper, :meth:`SolveFailure.at`), and its ``kind`` in one word (diverged,
  stagnated, too_many_iterations, damage_failed, non_finite, output_failed, singular), by which a
  table of runs tallies its failures:
  :class:`DisplacementSolveError` (``method``, ``reason``, ``iterations``, ``residuals``,
  ``tolerance``), :class:`DamageSolveError` (``reason``), :class:`NonFiniteError` (``fields``),
  :class:`OutputError` (``reason``: writing results failed, e.g. a full disk).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

# displacement-solver reasons -> the failure's kind
_KIND = {
    "DIVERGED_RESIDUAL_GROWTH": "diverged",
    "DIVERGED_FNORM_NAN": "diverged",
    "DIVERGED_STAGNATION": "stagnated",
    "DIVERGED_MAX_IT": "too_many_iterations",
    "DIVERGED_ACTIVE_SET_CYCLE": "too_many_iterations",  # stopped early: a cycle would run to max_it
}


class CampoError(Exception):
    """Base of every error the solver raises on purpose."""


# ----------------------------------------------------------------------------- input


class InputError(CampoError, ValueError):
    """The user's input is wrong: one line for the user, exit code 2."""


class ConfigError(InputError):
    """A scene is invalid: ``key`` = ``value`` is not ``allowed`` (in file ``source``).

    Raised either with the fields (the message is composed from them) or with a ready
    message for checks that are not about one key (a mesh that lacks a named group).
    """

    def __init__(self, message: str | None = None, *, source: str = "", key: str = "", value: Any = None,
                 allowed: str = "") -> None:
        self.source, self.key, self.value, self.allowed = source, key, value, allowed
        if message is None:
            message = f"{source}: {key} = {show(value)}: {allowed}" if source else f"{key} = {show(value)}: {allowed}"
        super().__init__(message)


class UsageError(InputError):
    """A mistake on the command line or with the results directory (exit code 2)."""


class OutputDirectoryError(UsageError):
    """A results directory a run may not write to (exit code 2 on the command line).

    ``directory``: the one asked for; ``problem``: one of :attr:`PROBLEMS`; ``existing``: the earlier results found
    there (``fields/`` for the series' data), for ``"earlier results"``."""

    PROBLEMS = ("not a directory", "earlier results", "no checkpoint", "cannot write")

    def __init__(self, message: str, directory: Any, problem: str, existing: tuple[str, ...] = ()) -> None:
        self.directory, self.problem, self.existing = Path(directory), problem, tuple(existing)
        super().__init__(message)


class ResultsError(UsageError):
    """A results directory that cannot be read: the file ``path`` and what is wrong with it (``reason``), e.g. a
    truncated ``.h5``, an XDMF naming a missing file or dataset, a CSV without a column (exit code 2)."""

    def __init__(self, path: Any, reason: str) -> None:
        self.path, self.reason = str(path), " ".join(str(reason).split())  # one line, whatever a library said
        super().__init__(f"{self.path}: {self.reason}")


def show(value: Any) -> str:
    """A value as the user wrote it: strings quoted, tables by their keys."""
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, dict):
        return "{" + ", ".join(value) + "}"
    return str(value)


class ToleranceError(InputError):
    """A tolerance the solver cannot reach within its limits: the best ``estimate`` at ``dofs`` is above
    ``tolerance`` (the user's, absolute), or above ``target``, the part of it one error term was given;
    ``limit`` names the setting that stopped it."""

    def __init__(self, tolerance: float, estimate: float, dofs: int, limit: str, target: float | None = None,
                 predicted: float | None = None) -> None:
        self.tolerance, self.estimate, self.dofs, self.limit, self.target = tolerance, estimate, dofs, limit, target
        self.predicted = predicted  # the dofs the tolerance would need, predicted before refining (None: found)
        part = "" if target is None else f" against its part {target:.3g}"
        need = "" if predicted is None else (f": it would need about {predicted:.3g} displacement dofs (predicted "
                                             "from the estimate's rate on the start mesh)")
        super().__init__(f"accuracy.tolerance = {tolerance:.3g} cannot be reached within {limit}{need} "
                         f"(estimate {estimate:.3g}{part} at {dofs} displacement dofs)")


# ----------------------------------------------------------------------------- interruption


class Interrupted(CampoError):
    """A run stopped on a signal (SIGINT, SIGTERM) at the end of level ``step`` (time ``t``), its results and a
    checkpoint written up to there; ``signal`` is the signal's number (the exit code is 128 + it)."""

    def __init__(self, signal: int, step: int, t: float, checkpoint: bool) -> None:
        self.signal, self.step, self.t, self.checkpoint = signal, step, t, checkpoint
        super().__init__(f"stopped at step {step}, t = {t:.6g}")


# ----------------------------------------------------------------------------- run failures


class SolveFailure(CampoError, RuntimeError):
    """A run stopped at a time level (exit code 1). ``step``/``t`` are None until the stepper sets them."""

    kind = "failed"

    def __init__(self, detail: str, *, step: int | None = None, t: float | None = None) -> None:
        self.detail, self.step, self.t = detail, step, t
        super().__init__(detail)

    def at(self, step: int, t: float) -> SolveFailure:
        """Record where it happened (the message then starts with the step and time)."""
        self.step, self.t = step, t
        self.args = (str(self),)
        return self

    def __str__(self) -> str:
        if self.step is None:
            return self.detail
        return f"step {self.step}, t = {self.t:.6g}: {self.detail}"


class DisplacementSolveError(SolveFailure):
    """The displacement problem of a level did not converge."""

    def __init__(self, method: str, reason: str, iterations: int, residuals: list[float], tolerance: float,
                 linear_reason: int = 0) -> None:
        self.method, self.reason, self.iterations = method, reason, iterations
        self.residuals, self.tolerance, self.linear_reason = list(residuals), tolerance, linear_reason
        tail = ", ".join(f"{r:.3e}" for r in self.residuals[-5:])
        linear = f", linear solve {linear_reason}" if linear_reason < 0 else ""
        super().__init__(f"displacement solve failed: {method} {reason}{linear}, {iterations} iterations, "
                         f"last residuals [{tail}] (tolerance {tolerance:.3e})")

    @property
    def kind(self) -> str:  # type: ignore[override]
        return _KIND.get(self.reason, "failed")


class DamageSolveError(SolveFailure):
    """The damage step failed: its linear solve, or the semi-implicit step's stability condition."""

    kind = "damage_failed"

    def __init__(self, reason: str, detail: str = "") -> None:
        self.reason = reason
        super().__init__(f"damage step failed: {reason}" + (f" ({detail})" if detail else ""))


class NonFiniteError(SolveFailure):
    """A field became NaN or inf."""

    kind = "non_finite"

    def __init__(self, fields: list[str]) -> None:
        self.fields = sorted(set(fields))
        super().__init__(f"non-finite values in {', '.join(self.fields)}")


class OutputError(SolveFailure):
    """Writing the results failed (a full disk, a vanished directory); what was written before stays readable.

    ``level_t``: the time of the level whose write failed, when it is known (levels are written in
    the background, so the failure may be found a few levels later; the stepper reports this one)."""

    kind = "output_failed"

    def __init__(self, reason: str, level_t: float | None = None) -> None:
        self.reason, self.level_t = reason, level_t
        super().__init__(f"writing results failed: {reason}")


class RigidMotionError(InputError):
    """The Dirichlet parts leave a rigid motion free, so the stiffness matrix is singular (found before solving).

    Bad input (the scene's supports), not a failed run: exit code 2 like any other scene mistake."""

    kind = "singular"

    def __init__(self, motions: list[str]) -> None:
        self.motions = list(motions)
        super().__init__("boundary: the Dirichlet parts leave a rigid motion free (" + "; ".join(self.motions) + "): "
                         "the stiffness matrix is singular; fix more displacement components")
