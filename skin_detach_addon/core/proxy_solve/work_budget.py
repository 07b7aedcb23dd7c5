"""Budgets of the proxy solve counted in work done, not read off the wall clock.

A unit of work is one conjugate-gradient step of the Newton solve (a Hessian product and a
preconditioner solve); the rest of a Newton iteration (the rotation fit, the gradient, the volume
tangent, the line search) counts :data:`ITERATION_UNITS`, a new Hessian factor
:data:`FACTOR_UNITS`. A solve given a :class:`WorkBudget` stops where its units run out, so it
gives the same iterate whatever the clock does: another program taking the core from the solve
no longer cuts it short (a drag's moves were cut to one conjugate-gradient step each, lagged
further behind with every move and the settle after them did not finish: the shown path grew, the
confirm popped).

Milliseconds become units through :class:`WorkRate`, the measured CPU time of the solving thread
(``time.thread_time``, which does not run while the thread waits for a core) per unit: a budget of
so many milliseconds is the work this machine does in that time when the solve has a core to
itself. A machine slower at the work itself (a smaller one, a core shared with its
hyperthread sibling) gets fewer units: a slower move does less, but never less than one Newton
iteration, and whatever it does is the work a quiet machine would do with that budget.
"""

import time

from ..errors import SkinDetachError

#: Units a Newton iteration costs besides its conjugate-gradient steps (the rotation fit, the
#: gradient and volume tangent with their preconditioner solves, the line search): measured 6-16
#: at 1,000 and 3,000 proxy faces (more with the volume kept).
ITERATION_UNITS = 8
#: Units a new factor of the Hessian costs (measured 27-35 at 1,000 and 3,000 proxy faces).
FACTOR_UNITS = 30
#: How much each CPU measurement a :class:`WorkRate` keeps weighs less than the next (about the last
#: ten solves count: a thread clock that ticks coarsely averages out).
RATE_DECAY = 0.9


class WorkBudget:
    """``units`` (a positive integer) of work a solve may spend; :meth:`spend` counts what it did."""

    def __init__(self, units):
        if isinstance(units, bool) or not isinstance(units, int) or units < 1:
            raise SkinDetachError(f"budget_units: expected a positive integer, got {units!r}")
        self.units = units
        self.spent = 0

    def spend(self, units):
        """Count ``units`` more of work done."""
        self.spent += units

    def would_pass(self, units):
        """Whether ``units`` more would end past the budget."""
        return self.spent + units > self.units

    @property
    def over(self):
        """Whether the budget is spent."""
        return self.spent >= self.units

    def past(self, overrun):
        """Whether more than ``overrun`` times the budget has been spent beyond it."""
        return self.spent > (1.0 + overrun) * self.units


class WorkRate:
    """CPU milliseconds of the solving thread per unit of work on this machine, for one solver:
    a first estimate ``first_ms`` (> 0), then every solve's CPU time over its units
    (:meth:`record`), the newer weighing more. Sums, not medians: a thread clock that ticks
    coarsely (Windows counts whole scheduler ticks) is right on average."""

    def __init__(self, first_ms):
        self._ms = float(first_ms)
        self._units = 1.0

    @property
    def ms_per_unit(self):
        return self._ms / self._units

    def budget(self, ms):
        """:class:`WorkBudget` of the units this machine does in ``ms`` milliseconds (at least one)."""
        return WorkBudget(max(1, int(ms / self.ms_per_unit)))

    def record(self, units, cpu_ms):
        """Count a solve that did ``units`` of work in ``cpu_ms`` milliseconds of its thread's CPU."""
        if units > 0 and cpu_ms >= 0.0:
            self._ms = RATE_DECAY * self._ms + cpu_ms
            self._units = RATE_DECAY * self._units + units


def cpu_ms():
    """Milliseconds of CPU time the calling thread has run (not the time it waited for a core)."""
    return 1000.0 * time.thread_time()
