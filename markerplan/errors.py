"""Exception roots. Every error we raise on purpose inherits from :class:`MarkerPlanError`
and from the builtin that describes it, so callers may catch either.

The CLI turns any ``MarkerPlanError`` into a one-line ``error: ...`` on stderr and exit code 1;
anything else is a bug and shows its traceback. Messages name the argument or file, state the
rule, show what was received and say how to fix it.
"""


class MarkerPlanError(Exception):
    """Root of all deliberate markerplan errors."""


class ConfigError(MarkerPlanError, ValueError):
    """An option, argument or configuration value is invalid."""


class InputFileError(MarkerPlanError, ValueError):
    """An input file is missing, unreadable or malformed."""


class DataError(MarkerPlanError, ValueError):
    """Input data is well-formed but unusable (empty scan, NaNs in a DEM, too few rows...)."""


class OutputError(MarkerPlanError, OSError):
    """The output location cannot be written, or exists and ``--overwrite`` was not given."""


class InfeasiblePlanError(MarkerPlanError, RuntimeError):
    """No marker layout can satisfy the requirement; the message names failing stations and why."""


class VerificationFailedError(MarkerPlanError, RuntimeError):
    """A plan was verified and some station's achieved error fails the requirement (or could not
    be measured); the message names the failing stations and why. The plan was feasible: this
    is the simulated survey's verdict, not the planner's."""


class PlanTimeLimitError(InfeasiblePlanError):
    """The search ended (its time limit, or the solver returned no layout) before any layout
    passed: nothing is proven infeasible, more time may find one."""
