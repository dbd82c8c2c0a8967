"""The skeleton: roles from a bones table or by name, the tree helpers, the unit guess, body radii by name."""
import numpy as np
import pytest

from lmm import skeleton as S

# LAFAN1 as a database holds it: the ground-projected simulation bone above the hips
NAMES = ["Simulation", "Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToe", "RightUpLeg", "RightLeg", "RightFoot",
         "RightToe", "Spine", "Spine1", "Spine2", "Neck", "Head", "LeftShoulder", "LeftArm", "LeftForeArm",
         "LeftHand", "RightShoulder", "RightArm", "RightForeArm", "RightHand"]
PARENTS = [-1, 0, 1, 2, 3, 4, 1, 6, 7, 8, 1, 10, 11, 12, 13, 12, 15, 16, 17, 12, 19, 20, 21]


def lafan1_offsets(cm=True):
    """Rest offsets of a 1.75 m body: legs of 0.43 + 0.43 m, in centimetres or metres."""
    off = np.zeros((len(NAMES), 3))
    for name, v in {"Hips": (0, 95, 0), "LeftUpLeg": (10, -5, 0), "LeftLeg": (0, -43, 0), "LeftFoot": (0, -43, 0),
                    "LeftToe": (0, -5, 12), "Spine": (0, 10, 0), "Spine1": (0, 12, 0), "Spine2": (0, 12, 0),
                    "Neck": (0, 15, 0), "Head": (0, 10, 0), "LeftShoulder": (5, 10, 0), "LeftArm": (12, 0, 0),
                    "LeftForeArm": (28, 0, 0), "LeftHand": (25, 0, 0)}.items():
        off[NAMES.index(name)] = v
        if name.startswith("Left"):
            off[NAMES.index("Right" + name[4:])] = (-v[0], v[1], v[2])
    return off if cm else off / 100.0


def test_manifest_defaults_and_checks_fallbacks_are_the_lafan1_names():
    assert S.default_bones() == {"hips": "Hips", "spine": "Spine2", "left_foot": "LeftFoot",
                                 "right_foot": "RightFoot", "left_toe": "LeftToe", "right_toe": "RightToe"}
    assert list(S.default_bones()) == list(S.MANIFEST_ROLES)
    assert S.joint_of_role(NAMES, None, "left_shoulder") == NAMES.index("LeftArm")
    assert S.joint_of_role(NAMES, {"hips": "Spine"}, "hips") == NAMES.index("Spine")    # the table wins
    assert S.joint_of_role(NAMES, {"hips": "Pelvis"}, "hips") is None                  # exact names only


def test_roles_by_synonyms_and_the_missing_ones_named():
    names = ["mixamorig:Hips", "mixamorig:Head", "l_wrist", "R_Wrist", "Foot_L", "RightAnkle"]
    assert S.match_roles(names, S.KEY_ROLES) == {k: i for i, k in enumerate(S.KEY_ROLES)}
    assert S.normalize_name("mixamorig:Left_Hand") == "lefthand"
    with pytest.raises(S.SkeletonMatchError, match=r"robot\.bvh: cannot match the key joints left_hand, right_hand "
                                                   r"by name \(accepted names, e\.g\. left_hand: lefthand, lhand"):
        S.match_roles(["Hips", "Head", "LeftFoot", "RightFoot"], S.KEY_ROLES, "robot.bvh")


def test_skeleton_roles_from_a_bones_table_then_by_name():
    sk = S.Skeleton.from_bones(NAMES, PARENTS, lafan1_offsets(), {**S.default_bones(), "hips": "Hips"}, 0.01)
    assert sk.hips == 1 and sk.joint("left_toe") == NAMES.index("LeftToe")
    assert sk.joint("head") == NAMES.index("Head")            # not in the table: by name
    assert sk.joint("Spine1") == NAMES.index("Spine1")        # a joint by name
    with pytest.raises(KeyError, match="no joint or role 'tail'"):
        sk.joint("tail")
    # a table naming another joint wins over the synonyms; names the skeleton lacks are skipped
    other = S.Skeleton.from_bones(NAMES, PARENTS, None, {"hips": "Spine", "head": "NoSuchJoint"})
    assert other.hips == NAMES.index("Spine") and other.joint("head") == NAMES.index("Head")
    assert sk.require(("left_hand", "right_foot")) == {"left_hand": 18, "right_foot": 8}
    with pytest.raises(S.SkeletonMatchError, match="the key joints head"):
        S.Skeleton.by_synonyms(["Hips"], [-1], None, 1.0).require(("hips", "head"), "x.bvh")
    assert np.allclose(sk.offsets_m[NAMES.index("LeftLeg")], [0, -0.43, 0])


def test_tree_helpers_against_their_definitions():
    parents = np.array(PARENTS)
    for j in range(len(PARENTS)):
        up = S.ancestors(parents, j)
        # ancestors: each the parent of the one before, ending at a root
        assert [int(parents[k]) for k in ([j] + up)[:len(up)]] == up and parents[([j] + up)[-1]] < 0
        # subtree: the joints with j among themselves and their ancestors
        assert S.subtree(parents, j) == [k for k in range(len(PARENTS)) if k == j or j in S.ancestors(parents, k)]
        assert S.children(parents, j) == [k for k in range(len(PARENTS)) if PARENTS[k] == j]
    hips, foot = 1, NAMES.index("LeftFoot")
    assert S.subtree(parents, [foot, NAMES.index("RightFoot")]) == [4, 5, 8, 9]
    assert S.chain(parents, hips, foot) == [foot, 3, 2, hips]
    with pytest.raises(ValueError, match="not an ancestor"):
        S.chain(parents, foot, hips)
    sk = S.Skeleton(NAMES, PARENTS, None)
    assert sk.subtree(foot) == [4, 5] and sk.find_toe(foot) == 5 and sk.find_toe(5) is None
    assert S.rest_positions(PARENTS, lafan1_offsets())[foot, 1] == pytest.approx(95 - 5 - 86)


@pytest.mark.parametrize("unit", [1.0, 0.1, 0.0254, 0.01, 0.001])
def test_the_unit_guess_makes_a_human_of_any_file(unit):
    offsets = lafan1_offsets(cm=False) / unit
    assert S.guess_unit_scale(NAMES, PARENTS, offsets) == unit
    # without named feet: the rest pose's height decides
    unnamed = [f"j{k}" for k in range(len(NAMES))]
    assert S.guess_unit_scale(unnamed, PARENTS, offsets) == unit
    assert S.Skeleton.by_synonyms(NAMES, PARENTS, offsets).unit_scale == unit
    assert S.guess_unit_scale(NAMES, PARENTS, np.zeros_like(offsets)) is None


def test_body_radii_by_name():
    r = dict(zip(NAMES, S.body_radii(NAMES)))
    assert r["Simulation"] == 0.0
    assert r["LeftUpLeg"] > r["LeftLeg"] > r["LeftFoot"]          # thigh, shin, ankle
    assert r["LeftArm"] > r["LeftForeArm"] and r["LeftArm"] == r["RightArm"]
    assert r["Spine2"] > r["Neck"] and r["Spine"] > r["LeftForeArm"] and r["Hips"] > r["LeftLeg"]
    assert 0.08 / 1.7 < r["Spine2"] < 0.15 / 1.7 and 0.03 / 1.7 < r["LeftForeArm"] < 0.05 / 1.7
    unknown = S.body_radii(["tail1", "wing_l", "Hips"])
    assert np.isnan(unknown[:2]).all() and unknown[2] == r["Hips"]
