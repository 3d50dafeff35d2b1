"""Robot loading, aliases, limits and random configurations."""

import numpy as np
import pytest

from hikbench.problems.errors import HikbenchError
from hikbench.problems.robots.models import ROBOTS, FrameNotFoundError, RobotNotFoundError, load_robot

EXPECTED_NV = {"talos": 38, "romeo": 61, "g1": 35, "tiago": 48, "panda": 9, "ur5": 6, "solo12": 18}


@pytest.mark.parametrize("name", list(ROBOTS))
def test_curated_robot_loads_with_its_aliases(name):
    robot = load_robot(name)
    assert robot.nv == EXPECTED_NV[name]
    for alias in robot.frames:
        robot.frame_id(alias)  # raises FrameNotFoundError if a frame is missing
    assert load_robot(name) is robot  # loaded once per process


@pytest.mark.parametrize("name", ["talos", "panda", "tiago", "solo12"])
def test_random_configuration_is_within_limits(name):
    robot = load_robot(name)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = robot.random_configuration(rng)
        assert q.shape == (robot.nq,)
        assert np.all(robot.limit_margin(q) > 0)


def test_free_flyer_is_unbounded(talos):
    assert talos.floating_base and not talos.bounded[:6].any()
    assert talos.nv - 6 == 32  # 32 joints + free flyer: the HRP-2 analogue


def test_unknown_robot_names_what_is_available():
    with pytest.raises(RobotNotFoundError, match=r"not in the installed example-robot-data.*talos"):
        load_robot("hrp2_not_a_robot")
    assert issubclass(RobotNotFoundError, HikbenchError)


def test_unknown_frame_names_the_aliases(panda):
    with pytest.raises(FrameNotFoundError, match=r"no frame 'right_hand'; expected an alias of robot 'panda' "
                                                 r"\(base, ee\).*set frames.right_hand = "):
        panda.frame_id("right_hand")
