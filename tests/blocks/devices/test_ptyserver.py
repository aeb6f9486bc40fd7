"""The pty link of an emulator replaces only a stale pty link and removes only its own (issue 30: a
graph or an emulator never replaces, deletes or appends to a file it does not own)."""

from __future__ import annotations

import os
import stat

import pytest

from flowtact.blocks.devices.ptyserver import LinkError, PtyServer, link_problem


class Silent:
    """A device that never speaks (only the link matters here)."""

    def next_due(self) -> float:
        return float("inf")

    def tick(self, now: float) -> list[bytes]:  # noqa: ARG002 - the LineDevice protocol
        return []

    def receive(self, line: bytes, now: float) -> list[bytes]:  # noqa: ARG002
        return []

    def plugged(self, now: float, first: bool) -> list[bytes]:  # noqa: ARG002
        return []


def others(tmp_path):
    """Things at a link path that belong to someone else, each with a way to see it is intact."""
    f = tmp_path / "data.csv"
    f.write_text("t,x\n0,1\n")
    d = tmp_path / "folder"
    d.mkdir()
    (d / "inside").write_text("kept")
    to_file = tmp_path / "to_file"
    to_file.symlink_to(f)
    dangling = tmp_path / "dangling"
    dangling.symlink_to(tmp_path / "not_yet")
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    return [f, d, to_file, dangling, fifo]


def snapshot(p):
    st = os.lstat(p)
    return (stat.S_IFMT(st.st_mode), st.st_ino, os.readlink(p) if os.path.islink(p) else None)


@pytest.mark.parametrize("which", range(5), ids=["file", "folder", "link-to-file", "dangling-link", "fifo"])
def test_a_path_that_is_not_a_pty_link_is_never_replaced(tmp_path, which):
    target = others(tmp_path)[which]
    before = snapshot(target)
    assert link_problem(str(target))
    server = PtyServer(Silent(), str(target))
    with pytest.raises(LinkError, match="never replaced"):
        server.open()
    server.close()
    assert snapshot(target) == before
    assert (tmp_path / "data.csv").read_text() == "t,x\n0,1\n"
    assert (tmp_path / "folder" / "inside").read_text() == "kept"
    assert sorted(os.listdir(tmp_path)) == sorted(["data.csv", "folder", "to_file", "dangling", "fifo"])


def test_a_new_link_and_a_stale_pty_link_are_served_and_removed(tmp_path):
    for link in (tmp_path / "new", tmp_path / "stale"):
        if link.name == "stale":
            link.symlink_to("/dev/pts/999999")  # an earlier emulator's pty, long gone
        server = PtyServer(Silent(), str(link))
        server.open()
        assert stat.S_ISCHR(os.stat(link).st_mode)
        server.close()
        assert not os.path.lexists(link)
    assert os.listdir(tmp_path) == []  # no temporary link left either


def test_close_leaves_whatever_replaced_its_link(tmp_path):
    link = tmp_path / "exo"
    server = PtyServer(Silent(), str(link))
    server.open()
    theirs = tmp_path / "theirs"
    theirs.write_text("someone's file")
    link.unlink()
    link.symlink_to(theirs)  # the path was taken over while the emulator ran
    server.close()
    assert os.readlink(link) == str(theirs) and theirs.read_text() == "someone's file"


def test_a_missing_folder_is_named(tmp_path):
    assert "does not exist" in link_problem(str(tmp_path / "no" / "exo"))
