"""The policies shipped in policies/ still work: an env or code change that silently breaks old
policies fails here. Each evaluation is deterministic (seeds 0-19), so a drop is a real change."""

from __future__ import annotations

from pathlib import Path

import pytest

from rlgrasp.compose import compose_eval
from rlgrasp.evaluation.cli import evaluate

POLICIES = Path(__file__).resolve().parents[1] / "policies"

# (file, objects to evaluate on, successes out of 20 when shipped, the floor asserted)
CASES = [
    ("grasp_objects_ppo.pt", "random_urdfs_test", 17, 14),
    ("grasp_ppo.pt", "cube", 17, 14),
    ("grasp_ppo_kuka_iiwa.pt", "cube", 18, 15),  # the checkpoint rebuilds its arm
    ("grasp_ppo_xarm6.pt", "cube", 17, 14),
    ("grasp_vision_depth.pt", "cube", 17, 14),  # a wrist depth camera student of grasp_ppo.pt
    ("pick_place_sac.pt", "cube", 19, 16),  # a goal task: the checkpoint rebuilds its task and goal
    ("grasp_sac", "cube", 19, 16),  # a policy folder (safetensors + JSON), shipped as nothing else
    ("grasp_vision_sac", "cube", 18, 15),  # a camera policy folder: SAC from the wrist depth camera
    ("grasp_vision_sac_rgb", "cube", 16, 13),  # SAC from the wrist RGB camera, a policy folder too
]


@pytest.mark.parametrize(
    ("name", "objects", "shipped", "floor"),
    # the quick set checks the default policy; CI all of them
    [case if case[0] == "grasp_ppo.pt" else pytest.param(*case, marks=pytest.mark.full) for case in CASES],
)
def test_shipped_policy_still_succeeds(
    tmp_path: Path, name: str, objects: str, shipped: int, floor: int
) -> None:
    m = evaluate(
        compose_eval(
            [
                f"ckpt={POLICIES / name}",
                f"objects={objects}",
                "episodes=20",
                "video=false",
                "plots=false",
                "teacher=none",
                f"outputs_root={tmp_path}",
                "name=ship",
            ]
        )
    )
    successes = m["success_at_end"]["successes"]
    assert successes >= floor, f"{name} on {objects}: {successes}/20 (shipped with {shipped}/20)"
