import control
import numpy as np
from numpy.testing import assert_allclose

from rrr_pin.dynamics import load_robot
from rrr_pin.study import StudyConfig, run_study

K18 = control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                 [1.0, 513.37 + 0.19, 513.37 * 0.19])


def test_results_do_not_depend_on_jobs():
    robot = load_robot("rrr")
    runs = [run_study(robot, K18, config=StudyConfig(duration=0.5, samples=2, jobs=j))
            for j in (1, 2)]
    a, b = (r.to_json() for r in runs)
    assert a["uncertain"]["samples"] == b["uncertain"]["samples"]
    assert a["summary"] == b["summary"]


def test_summary_is_computed_from_the_samples():
    result = run_study(load_robot("rrr"), K18,
                       config=StudyConfig(duration=0.5, samples=3, jobs=1, seed=2))
    data = result.to_json()
    s = data["summary"]
    assert s["samples_ok"] == 3
    # Recompute the headline ratio straight from the trajectories (not from the metrics).
    err = {k: np.concatenate([x["trajectories"][k].error.ravel() for x in result.samples])
           for k in ("fl", "hinf")}
    tau = {k: np.concatenate([x["trajectories"][k].tau.ravel() for x in result.samples])
           for k in ("fl", "hinf")}

    def rms(v):
        return np.sqrt(np.mean(v**2))

    assert_allclose(s["error_ratio_uncertain"], rms(err["fl"]) / rms(err["hinf"]), rtol=1e-12)
    assert_allclose(s["torque_ratio_uncertain"], rms(tau["hinf"]) / rms(tau["fl"]), rtol=1e-12)
    assert len(s["error_ratio_uncertain_per_joint"]) == 3
    assert set(data["nominal"]) == {"fl", "hinf"}
    assert len(data["uncertain"]["fl"]["rms_error"]) == 3
