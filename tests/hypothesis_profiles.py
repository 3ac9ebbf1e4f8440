"""Hypothesis profiles for the fuzz tests (tests/test_fuzz.py).

``HYPOTHESIS_PROFILE=fuzz`` (what ``make fuzz`` sets) selects the long run; anything else,
or nothing, the quick one that ``make test`` runs. The profiles are registered here and
applied per test through :data:`FUZZ` (a ``settings`` object), never loaded globally, so
the other test files' own ``@settings`` stay as their authors chose.

Rules, with the reason for each value:

* ``deadline=None`` everywhere: a case that sometimes takes 300 ms on a loaded CI machine is
  not a failure; real hangs are caught by the fuzz tests' own watchdog instead.
* quick: ``derandomize=True`` so ``make test`` explores the same cases on every machine and
  run (a green CI stays green unless the code changes), ``database=None`` so no
  ``.hypothesis`` folder appears in the checkout.
* fuzz: random exploration (a new seed every run, ``--hypothesis-seed=N`` to repeat one),
  ``print_blob`` so a failure prints the line that reproduces it.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, Phase, settings

#: Cases per fuzz test in the quick profile: enough to pass every case kind (generated,
#: mutated real file, random bytes) several times for each reader while keeping the whole
#: of test_fuzz.py to a few seconds per test.
QUICK_EXAMPLES = 120
#: Cases per fuzz test under ``make fuzz``: the issue asks for at least 10,000 per reader and
#: per loader; each reader and each loader has its own test.
FUZZ_EXAMPLES = 10_000

#: No "explain" phase: it re-runs a failing case under line tracing, 10-100x slower, which
#: trips the fuzz tests' hang watchdog and reports a Hang instead of the real failure.
_PHASES = [Phase.explicit, Phase.reuse, Phase.generate, Phase.target, Phase.shrink]

_SUPPRESSED = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much,
               HealthCheck.large_base_example]

settings.register_profile("quick", max_examples=QUICK_EXAMPLES, deadline=None, derandomize=True,
                          database=None, suppress_health_check=_SUPPRESSED, print_blob=True,
                          phases=_PHASES)
settings.register_profile("fuzz", max_examples=FUZZ_EXAMPLES, deadline=None, derandomize=False,
                          database=None, suppress_health_check=_SUPPRESSED, print_blob=True,
                          phases=_PHASES)

#: The profile in force for this run.
PROFILE = "fuzz" if os.environ.get("HYPOTHESIS_PROFILE", "").strip().lower() == "fuzz" else "quick"

#: Decorator for the fuzz tests: ``@FUZZ`` then ``@given(...)``.
FUZZ = settings(settings.get_profile(PROFILE))
