"""Budgets of the proxy solve counted in work done, never read off a clock.

A unit of work is one conjugate-gradient step of the Newton solve (a Hessian product and a
preconditioner solve); the rest of a Newton iteration (the rotation fit, the gradient, the volume
tangent, the line search) counts :data:`ITERATION_UNITS`, a new Hessian factor
:data:`FACTOR_UNITS`. A solve given a :class:`WorkBudget` stops where its units run out, so it
gives the same iterate whatever the clock does.

A drag's budgets are fixed numbers of units (:func:`scaled_units`: set at a 1,000-face proxy and
scaled by the solver's free vertices, so a larger proxy's move does fewer, dearer units and stays
about as long): the shapes a drag shows are a function of its events alone. They were once
milliseconds turned into units at the solving thread's measured CPU time per unit; that rate
moved with the machine's load, its caches and the timing of the first unit, every move's budget
with it (4 ms: 5 or 6 units at 1,000 faces beside another process on a 2-core machine, more on a
quiet one), and the solve continued from another iterate: the same drag followed its path in
one run and flailed in the next (issue 53).
"""

from ..errors import SkinDetachError

#: Units a Newton iteration costs besides its conjugate-gradient steps (the rotation fit, the
#: gradient and volume tangent with their preconditioner solves, the line search): measured 6-16
#: at 1,000 and 3,000 proxy faces (more with the volume kept).
ITERATION_UNITS = 8
#: Units a new factor of the Hessian costs (measured 27-35 at 1,000 and 3,000 proxy faces).
FACTOR_UNITS = 30
#: Free proxy vertices of the solve a :func:`scaled_units` budget is given for (about a 1,000-face
#: proxy's, less its handles and anchors).
REFERENCE_FREE = 400


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

    def make_room(self, units, most):
        """Raise the budget so that ``units`` more fit, to at most ``most`` units in all; whether
        they fit now."""
        self.units = max(self.units, min(self.spent + units, int(most)))
        return not self.would_pass(units)

    def past(self, overrun):
        """Whether more than ``overrun`` times the budget has been spent beyond it."""
        return self.spent > (1.0 + overrun) * self.units


def scaled_units(units, free):
    """Units of a budget of ``units`` at :data:`REFERENCE_FREE` free vertices for a solve of ``free``
    free vertices (a unit's cost grows about linearly with them): at least one, the same for the
    same solver on every machine."""
    return max(1, int(round(units * REFERENCE_FREE / max(int(free), 1))))
