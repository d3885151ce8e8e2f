"""Disk margins of the three-axis quaternion loop on the flexible spacecraft: each axis's equals
python-control's on that axis's loop with the other two closed, all axes at once is no larger
than any one, a delay only takes margin away, and an unstable loop has none."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.analysis.spatial_loops import (DiskMargins, quaternion_disk_margins,
                                                quaternion_loop)
from controllers.feedback.quaternion import QuaternionFeedback
from flexctl import SpatialAppendage, SpatialHub, SpatialStructure
from flexctl.model.errors import InputTypeError, InputValueError
from spatial_craft import INERTIA, WING

REST = (1.0, 0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def craft():
    return SpatialStructure(hub=SpatialHub(inertia=np.array(INERTIA), radius=0.06),
                            appendages=(SpatialAppendage(**WING),))


@pytest.fixture(scope="module")
def law(craft):
    return QuaternionFeedback.design(craft.rigid_inertia, 0.5, REST, integral_time=20.0)


@pytest.mark.parametrize("skew", [-0.5, 0.0, 0.5])
def test_each_axis_is_python_controls_margin_with_the_other_loops_closed(craft, law, skew):
    import control

    margins = quaternion_disk_margins(law, craft, n_modes=2, skew=skew)
    assert margins.closed_loop_stable and isinstance(margins, DiskMargins)
    loop = quaternion_loop(law, craft, n_modes=2)
    omega = np.unique(np.concatenate([np.logspace(-3, 4, 6000), margins.frequency]))
    for axis in range(3):
        others = np.eye(3)
        others[axis, axis] = 0.0
        alone = control.feedback(loop, others)[axis, axis]
        dm, dgm, dpm = control.disk_margins(alone, omega, skew=skew)
        assert margins.disk_margin[axis] == pytest.approx(dm, rel=1e-3)
        assert margins.gain_margin_db[axis] == pytest.approx(dgm, rel=1e-3)
        assert margins.phase_margin_deg[axis] == pytest.approx(dpm, rel=1e-3)


def test_all_axes_at_once_is_no_larger_than_one_at_a_time(craft, law):
    margins = quaternion_disk_margins(law, craft, n_modes=2)
    alpha, gain, phase = margins.multiloop
    assert 0.0 < alpha <= np.min(margins.disk_margin) * (1 + 1e-6)
    assert gain <= np.min(margins.gain_margin_db) + 1e-6
    assert phase <= np.min(margins.phase_margin_deg) + 1e-6


def test_a_delay_takes_margin_away(craft, law):
    prompt = quaternion_disk_margins(law, craft, n_modes=2)
    late = quaternion_disk_margins(law, craft, n_modes=2, delay=1e-3)
    assert late.closed_loop_stable
    assert np.all(late.disk_margin < prompt.disk_margin)
    assert np.all(late.phase_margin_deg < prompt.phase_margin_deg)


def test_an_unstable_loop_has_no_margin(craft):
    fast = QuaternionFeedback.design(craft.rigid_inertia, 5.0, REST)
    margins = quaternion_disk_margins(fast, craft, n_modes=2, delay=0.05)
    assert not margins.closed_loop_stable and margins.spectral_abscissa > 0.0
    assert np.all(margins.disk_margin == 0.0) and "UNSTABLE" in str(margins)


@pytest.mark.parametrize("change, error, match", [
    (dict(law="kp"), InputTypeError, r"quaternion_loop\.law"),
    (dict(delay=-0.1), InputValueError, r"quaternion_loop\.delay"),
    (dict(skew=2.0), InputValueError, r"quaternion_disk_margins\.skew"),
])
def test_bad_arguments_are_refused_by_name(craft, law, change, error, match):
    arguments = dict(law=law, structure=craft, n_modes=2)
    arguments.update(change)
    with pytest.raises(error, match=match):
        quaternion_disk_margins(arguments.pop("law"), arguments.pop("structure"), **arguments)


def test_a_law_holding_a_rate_is_refused(craft):
    spinning = QuaternionFeedback(target=REST, kp=1.0, kd=1.0, target_rate=(0.0, 0.0, 0.1))
    with pytest.raises(InputValueError, match="target_rate must be zero"):
        quaternion_loop(spinning, craft, n_modes=2)
