"""Learned tuning plumbing: PPO/SAC train on vectorised randomised envs, checkpoint, resume,
and a saved policy tunes a machine it has not seen in at most 5 runs. (The training here is
tiny: it checks the plumbing, not the policy's quality; see the report for the full run.)"""

import base64
import json
import pathlib
import pickle
import shutil
import zipfile
from pathlib import Path

import pytest

from tuning.compare import compare_policy_to_cma, held_out_machines
from tuning.jobs import TuneSpec, tune
from tuning.sb3_job import MANIFEST, apply_policy, latest_checkpoint, train
from twin.errors import ConfigError


@pytest.fixture(scope="module")
def ppo(tmp_path_factory):
    out = tmp_path_factory.mktemp("ppo")
    costs: list[float] = []
    path = train("ppo", machine="tomsk_xy", program="tiny", out_dir=out, total_steps=32,
                 n_envs=2, checkpoint_steps=16, rollout=16, on_cost=costs.append,
                 tensorboard=out.parent / "tb")
    return out, path, costs


def test_training_writes_checkpoints_a_policy_and_tensorboard_logs(ppo):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    out, path, costs = ppo
    assert path.is_file() and path.name == "policy.zip"
    assert latest_checkpoint(out).name == "policy_32_steps.zip"
    # every training run's cost reached the job (the convergence plot's training panel)
    assert len(costs) == 32 and all(c > 0 for c in costs)
    (run,) = (out.parent / "tb").iterdir()
    assert run.name.startswith("ppo_")
    events = EventAccumulator(str(run))
    events.Reload()
    tags = set(events.Tags()["scalars"])
    assert {"train/loss", "train/learning_rate"} <= tags, tags


def test_training_resumes_from_the_newest_checkpoint(ppo, tmp_path):
    out, _, _ = ppo
    from stable_baselines3 import PPO

    resumed = tmp_path / "resume"
    shutil.copytree(out, resumed)      # the job's folder, manifest included
    path = train("ppo", machine="tomsk_xy", program="tiny", out_dir=resumed,
                 total_steps=48, n_envs=1, checkpoint_steps=16, rollout=16, resume=True)
    assert PPO.load(path).num_timesteps == 48     # 32 resumed + 16 new, not 48 new
    assert latest_checkpoint(resumed).name == "policy_48_steps.zip"
    listed = json.loads((resumed / MANIFEST).read_text())
    assert {"policy_16_steps.zip", "policy_32_steps.zip", "policy_48_steps.zip",
            "policy.zip"} <= set(listed)


def _planted(genuine: Path, path: Path, marker: Path) -> Path:
    """A copy of a genuine checkpoint whose data carries a pickle that creates ``marker``
    when it is loaded: what an attacker would drop into the folder."""
    payload = base64.b64encode(pickle.dumps(_Touch(str(marker)))).decode()
    with zipfile.ZipFile(genuine) as src, zipfile.ZipFile(path, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "data":
                doc = json.loads(data)
                doc["planted"] = {":type:": "<class 'object'>", ":serialized:": payload}
                data = json.dumps(doc).encode()
            dst.writestr(item, data)
    return path


class _Touch:
    def __init__(self, path: str):
        self.path = path

    def __reduce__(self):
        return (pathlib.Path.touch, (pathlib.Path(self.path),))


def test_a_planted_checkpoint_is_never_loaded(ppo, tmp_path):
    out, _, _ = ppo
    folder, marker = tmp_path / "job", tmp_path / "code-ran"
    shutil.copytree(out, folder)
    _planted(out / "policy_32_steps.zip", folder / "policy_64_steps.zip", marker)
    # the proof that the file is live: SB3 runs its pickle on load
    from stable_baselines3 import PPO
    PPO.load(folder / "policy_64_steps.zip")
    assert marker.exists()
    marker.unlink()
    # without --resume nothing found in the folder is loaded: training starts afresh
    path = train("ppo", machine="tomsk_xy", program="tiny", out_dir=folder, total_steps=16,
                 n_envs=1, checkpoint_steps=16, rollout=16)
    assert not marker.exists() and PPO.load(path).num_timesteps == 16
    # with it, the file the manifest does not list is refused, not loaded
    with pytest.raises(ConfigError, match=r"policy_64_steps\.zip is not in .*did not write it"):
        train("ppo", machine="tomsk_xy", program="tiny", out_dir=folder, total_steps=64,
              n_envs=1, checkpoint_steps=16, rollout=16, resume=True)
    assert not marker.exists()


def test_a_checkpoint_changed_since_it_was_written_is_refused(ppo, tmp_path):
    out, _, _ = ppo
    folder, marker = tmp_path / "job", tmp_path / "code-ran"
    shutil.copytree(out, folder)
    _planted(out / "policy_32_steps.zip", folder / "policy_32_steps.zip", marker)  # replaced
    with pytest.raises(ConfigError, match="does not match the SHA-256"):
        train("ppo", machine="tomsk_xy", program="tiny", out_dir=folder, total_steps=48,
              n_envs=1, checkpoint_steps=16, rollout=16, resume=True)
    assert not marker.exists()


def test_policy_tunes_an_unseen_machine_in_five_runs(ppo):
    _, path, _ = ppo
    machine = held_out_machines("tomsk_xy", 1)[0]
    trials, baseline = apply_policy(path, machine, program="tiny", runs=5)
    assert 1 <= len(trials) <= 5
    assert baseline.x == (0.0,) * 11
    assert all(len(t.x) == 11 and all(-1 <= v <= 1 for v in t.x) for t in trials)
    assert trials[0].cost == pytest.approx(sum(trials[0].terms.values()), rel=1e-12)


def test_compare_plumbing(ppo):
    _, path, _ = ppo
    rows = compare_policy_to_cma(path, held_out_machines("tomsk_xy", 1), program="tiny",
                                 cma_max_runs=8, workers=1)
    (row,) = rows
    assert row["cma_runs"] == 8 and row["policy_runs"] <= 5
    assert row["ratio"] == pytest.approx(row["policy_cost"] / row["cma_cost"])
    assert row["cma_cost"] <= row["analytic_cost"] and row["policy_cost"] <= row["analytic_cost"]


def test_sac_trains_and_applies(tmp_path):
    path = train("sac", machine="tomsk_xy", program="tiny", out_dir=tmp_path, total_steps=12,
                 n_envs=1, checkpoint_steps=6, rollout=8)
    assert (tmp_path / "policy_replay_buffer_12_steps.pkl").is_file()
    trials, _ = apply_policy(path, "tomsk_xy", program="tiny", runs=2)
    assert len(trials) == 2


def test_ppo_job_with_a_given_policy(ppo, tmp_path):
    _, path, _ = ppo
    result = tune(TuneSpec(method="ppo", program="tiny", policy=path, out_dir=tmp_path,
                           policy_runs=3))
    assert len(result.trials) == 3 and result.files["overrides"].is_file()
    assert "policy" not in result.files   # nothing was trained


def test_policy_errors(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        apply_policy(tmp_path / "none.zip", "tomsk_xy")
    junk = tmp_path / "junk.zip"
    junk.write_bytes(b"not a zip")
    with pytest.raises(ConfigError, match="not a PPO or SAC policy"):
        apply_policy(junk, "tomsk_xy")
    with pytest.raises(ConfigError, match="method"):
        train("a2c", machine="tomsk_xy", out_dir=tmp_path, total_steps=1)


def test_a_manifest_nested_too_deep_lists_nothing(tmp_path):
    """A manifest that would take Python's JSON parser past its stack (issue 33) is no
    manifest: nothing in the folder is trusted, and nothing is raised."""
    (tmp_path / MANIFEST).write_text('{"policy_16_steps.zip": ' + "[" * 100_000
                                     + "]" * 100_000 + "}")
    (tmp_path / "policy_16_steps.zip").write_bytes(b"not a checkpoint")
    with pytest.raises(ConfigError, match="not in"):
        latest_checkpoint(tmp_path)

