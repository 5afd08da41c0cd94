"""Which tracker the roft_sim plugin's fixtures (make_tracker, tracker_config) serve.

Overriding ``tracker_under_test`` tests the tracker straight from the source tree. Once the
package is installed (its entry point registers ``my-cv-tracker``), ``pytest
--roft-sim-tracker my-cv-tracker`` or ``roft_sim_tracker = "my-cv-tracker"`` in pyproject.toml
does the same without this file.
"""

import pytest
from my_tracker import SPEC


@pytest.fixture
def tracker_under_test():
    return SPEC
