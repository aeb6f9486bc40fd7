"""Block examples write their files into a private folder of their own process, never at a name
another local user could plant in the shared temp directory (a symlink to one of our files).

The examples run in a child whose temp directory is this test's folder; before they run, the child
plants symlinks at every name the examples used to write (replay, replay_ports, camera), pointing
at a file and a folder that must stay untouched."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys

CHILD = r"""
import json, os, sys, tempfile
from pathlib import Path

tmp, pid = Path(tempfile.gettempdir()), os.getpid()
victim, victim_dir = Path(sys.argv[1]), Path(sys.argv[2])
for name, target in {
    "flowtact-camera-example-v1": victim_dir,
    f"flowtact-replay-example-v1-{pid}.npz": victim,
    f"flowtact-replay-example-v1-{pid}.npz.{pid}.tmp.npz": victim,
    f"flowtact-replay-ports-aunp_sensor-v1-{pid}.csv": victim,
    f"flowtact-replay-ports-aunp_sensor-v1-{pid}.csv.tmp": victim,
}.items():
    (tmp / name).symlink_to(target)

from flowtact.blocks.signal.replay import Replay
from flowtact.blocks.signal.replay_ports import stand_in_class
from flowtact.blocks.teleop.camera import Camera

paths = [
    Replay.example().params["path"],
    stand_in_class("aunp_sensor").example().params["path"],
    *Camera.example().params["devices"],
]
tops = {str(tmp / Path(p).relative_to(tmp).parts[0]) for p in paths}
folders = {t: [os.lstat(t).st_mode, os.lstat(t).st_uid] for t in tops}
print(json.dumps({"paths": paths, "folders": folders}))
"""


def test_examples_write_into_a_private_folder_and_never_follow_a_planted_link(tmp_path):
    temp = tmp_path / "tmp"
    temp.mkdir()
    victim, victim_dir = tmp_path / "precious.txt", tmp_path / "precious"
    victim.write_text("keep me")
    victim_dir.mkdir()
    env = {**os.environ, "TMPDIR": str(temp)}
    done = subprocess.run(
        [sys.executable, "-c", CHILD, str(victim), str(victim_dir)],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout.splitlines()[-1])
    assert victim.read_text() == "keep me"
    assert list(victim_dir.iterdir()) == []
    for path in out["paths"]:
        assert os.path.realpath(path) == path, path  # no link on the way
        assert not os.path.basename(os.path.dirname(path)).startswith("flowtact-replay"), path
    assert len(out["folders"]) == 1, out["folders"]  # one folder per process
    for folder, (mode, uid) in out["folders"].items():
        assert os.path.basename(folder).startswith("flowtact-example-")
        assert stat.S_ISDIR(mode) and stat.S_IMODE(mode) == 0o700 and uid == os.getuid()
        assert not os.path.lexists(folder)  # removed when the child exited
