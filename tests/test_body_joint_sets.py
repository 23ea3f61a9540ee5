"""Joint tables against smplx's own joint-name list (the independent reference)."""
import numpy as np
import smplx.joint_names

from airpose_lib.body import (
    BODY22_NAMES,
    BODY_25_EDGES,
    BODY_25_FROM_SMPLX,
    BODY_25_NAMES,
    COCO17_FROM_SMPLX,
    COCO17_NAMES,
    COCO18_FROM_SMPLX,
    COCO18_NAMES,
    OUTPUT_JOINT_NAMES,
    SMPLX_JOINT_NAMES,
    SMPLX_PARENTS,
    joint_index,
)
from airpose_lib.body.joint_sets import (
    left_right_permutation,
)

REF = smplx.joint_names.JOINT_NAMES


def test_output_joint_names_follow_smplx_order():
    assert list(OUTPUT_JOINT_NAMES) == REF[:76]
    assert len(SMPLX_JOINT_NAMES) == 55


def test_body22_is_pelvis_to_wrists():
    assert BODY22_NAMES[0] == "pelvis" and BODY22_NAMES[-1] == "right_wrist"
    assert len(BODY22_NAMES) == 22


def test_parents_form_a_tree_rooted_at_pelvis():
    assert SMPLX_PARENTS[0] == -1
    for child, parent in enumerate(SMPLX_PARENTS[1:], start=1):
        assert 0 <= parent < child
    # spot checks from the SMPL-X kinematic tree
    assert SMPLX_PARENTS[joint_index("left_elbow")] == joint_index("left_shoulder")
    assert SMPLX_PARENTS[joint_index("right_thumb1")] == joint_index("right_wrist")
    assert SMPLX_PARENTS[joint_index("left_pinky3")] == joint_index("left_pinky2")
    assert SMPLX_PARENTS[joint_index("jaw")] == joint_index("head")


def _name_matches(keypoint: str, smplx_name: str) -> bool:
    if keypoint[0] in "LR" and keypoint[1].isupper():  # OpenPose style: LBigToe, RShoulder
        keypoint = {"L": "left", "R": "right"}[keypoint[0]] + keypoint[1:]
    return keypoint.lower().replace("_", "") == smplx_name.replace("_", "")


def test_body25_mapping():
    assert len(BODY_25_FROM_SMPLX) == 25
    for name, idx in zip(BODY_25_NAMES, BODY_25_FROM_SMPLX):
        if name == "MidHip":
            assert REF[idx] == "pelvis"
        else:
            assert _name_matches(name, REF[idx]), (name, REF[idx])
    assert all(0 <= a < 25 and 0 <= b < 25 for a, b in BODY_25_EDGES)


def test_coco_mappings():
    for names, table in ((COCO17_NAMES, COCO17_FROM_SMPLX), (COCO18_NAMES, COCO18_FROM_SMPLX)):
        assert len(table) == len(names)
        for name, idx in zip(names, table):
            assert _name_matches(name, REF[idx]), (name, REF[idx])


def test_unknown_joint_name_is_a_clear_error():
    import pytest

    with pytest.raises(KeyError, match="unknown SMPL-X joint"):
        joint_index("left_tail")


def test_body_pose_from_named_joints_matches_scipy():
    import numpy as np
    import pytest
    from scipy.spatial.transform import Rotation

    from airpose_lib.body import axis_angle, body_pose_from_joints

    aa = axis_angle(("z", -1.2), ("x", 0.3))
    expected = (Rotation.from_rotvec([0.3, 0, 0]) * Rotation.from_rotvec([0, 0, -1.2])).as_rotvec()
    np.testing.assert_allclose(aa, expected, atol=1e-12)
    pose = body_pose_from_joints({"left_knee": [1.0, 0.0, 0.0]}).reshape(21, 3)
    assert pose[joint_index("left_knee") - 1, 0] == 1.0 and np.count_nonzero(pose) == 1
    with pytest.raises(KeyError, match="21 body joints"):
        body_pose_from_joints({"jaw": [0.1, 0, 0]})


def test_left_right_permutation():
    perm = left_right_permutation(BODY_25_NAMES)
    assert BODY_25_NAMES[perm[BODY_25_NAMES.index("LWrist")]] == "RWrist"
    assert BODY_25_NAMES[perm[BODY_25_NAMES.index("RHeel")]] == "LHeel"
    assert perm[BODY_25_NAMES.index("Nose")] == BODY_25_NAMES.index("Nose")
    assert np.array_equal(perm[perm], np.arange(25))  # an involution
    arms = left_right_permutation(COCO18_NAMES, ("Shoulder", "Elbow", "Wrist"))
    assert COCO18_NAMES[arms[COCO18_NAMES.index("LElbow")]] == "RElbow"
    assert arms[COCO18_NAMES.index("LKnee")] == COCO18_NAMES.index("LKnee")
