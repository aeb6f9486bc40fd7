"""CurveZMQ for off-host streams: keys on disk, the rig-only authenticator, and clear handshake errors."""

from __future__ import annotations

import contextlib
import socket
import stat
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import zmq

from flowtact.errors import SecurityError
from flowtact.runtime.links.zeromq.security import (
    ENV_VAR,
    PUBLIC_FILE,
    SECRET_FILE,
    Authenticator,
    CurveKeys,
    HandshakeWatch,
    generate_keys,
    is_loopback,
    load_keys,
    secure_client,
    secure_server,
)

pytestmark = pytest.mark.timeout(20)

PAYLOAD = b"tactile-secret-payload-0123456789"


@pytest.fixture
def keys(tmp_path: Path) -> CurveKeys:
    return load_keys(generate_keys(tmp_path / "keys"))


@pytest.fixture
def other_keys(tmp_path: Path) -> CurveKeys:
    return load_keys(generate_keys(tmp_path / "other"))


class Net:
    """One context and everything made in it, closed in reverse order (so ``ctx.term()`` cannot hang)."""

    def __init__(self) -> None:
        self.ctx = zmq.Context()
        self.stack = contextlib.ExitStack()

    def socket(self, kind: int) -> zmq.Socket:
        sock = self.ctx.socket(kind)
        sock.linger = 0
        self.stack.callback(sock.close, 0)
        return sock

    def watch(self, sock: zmq.Socket) -> HandshakeWatch:
        return self.stack.enter_context(HandshakeWatch(sock))

    def authenticator(self, keys: CurveKeys) -> Authenticator:
        return self.stack.enter_context(Authenticator(self.ctx, keys))

    def server(self, keys: CurveKeys) -> tuple[zmq.Socket, str]:
        pull = self.socket(zmq.PULL)
        secure_server(pull, keys)
        port = pull.bind_to_random_port("tcp://127.0.0.1")
        return pull, f"tcp://127.0.0.1:{port}"

    def close(self) -> None:
        self.stack.close()


@pytest.fixture
def net() -> Iterator[Net]:
    before = {t.ident for t in threading.enumerate()}
    made = Net()
    yield made
    made.close()
    made.ctx.term()  # hangs (and the timeout fails the test) if a socket was left open
    left = [t for t in threading.enumerate() if t.ident not in before and t.is_alive()]
    assert not left, f"threads left running: {left}"


# ------------------------------------------------------------------------------------------ key files


def test_generate_keys_writes_a_matching_pair_with_a_private_secret(tmp_path: Path) -> None:
    directory = generate_keys(tmp_path / "rig")
    assert directory == tmp_path / "rig"
    assert stat.S_IMODE((directory / SECRET_FILE).stat().st_mode) == 0o600
    assert sorted(p.name for p in directory.iterdir()) == [PUBLIC_FILE, SECRET_FILE]  # no temp dir left
    keys = load_keys(directory)
    assert zmq.curve_public(keys.secret) == keys.public
    assert keys.source == str(directory)
    assert keys.secret.decode() not in repr(keys)


def test_generate_keys_refuses_to_overwrite_unless_forced(tmp_path: Path) -> None:
    first = load_keys(generate_keys(tmp_path))
    with pytest.raises(SecurityError, match="already exists"):
        generate_keys(tmp_path)
    assert load_keys(tmp_path) == first
    generate_keys(tmp_path, force=True)
    assert load_keys(tmp_path).public != first.public


def test_missing_keys_give_a_hint(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ENV_VAR, raising=False)
    with pytest.raises(SecurityError, match=r"none are configured.*flowtact keys DIR.*network\.keys"):
        load_keys(None)
    with pytest.raises(SecurityError, match=r"does not exist.*flowtact keys DIR.*FLOWTACT_KEYS"):
        load_keys(tmp_path / "nowhere")
    with pytest.raises(SecurityError, match=f"has no {SECRET_FILE}"):
        load_keys(tmp_path)


def test_keys_come_from_the_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    expected = load_keys(generate_keys(tmp_path))
    monkeypatch.setenv(ENV_VAR, str(tmp_path))
    from_env = load_keys(None)
    assert (from_env.public, from_env.secret) == (expected.public, expected.secret)
    assert ENV_VAR in from_env.source


def test_malformed_or_mismatched_certificates_are_refused(tmp_path: Path) -> None:
    generate_keys(tmp_path / "a")
    generate_keys(tmp_path / "b")
    (tmp_path / "a" / PUBLIC_FILE).write_bytes((tmp_path / "b" / PUBLIC_FILE).read_bytes())
    with pytest.raises(SecurityError, match="different keys"):
        load_keys(tmp_path / "a")
    secret = tmp_path / "b" / SECRET_FILE
    secret.write_text(secret.read_text().replace('secret-key = "', 'secret-key = "x'))
    with pytest.raises(SecurityError, match="not a valid CURVE secret"):
        load_keys(tmp_path / "b")


@pytest.mark.parametrize(
    ("host", "loopback"),
    [
        ("127.0.0.1", True),
        ("127.3.2.1", True),
        ("localhost", True),
        ("LOCALHOST", True),
        ("::1", True),
        ("[::1]", True),
        ("::ffff:127.0.0.1", True),
        ("10.0.0.2", False),
        ("0.0.0.0", False),
        ("*", False),
        ("rig-host.lab", False),
        ("128.0.0.1", False),
    ],
)
def test_is_loopback(host: str, loopback: bool) -> None:
    assert is_loopback(host) is loopback


# ------------------------------------------------------------------------------------------ handshakes


class _Tap:
    """A TCP relay that records every byte the client sends to the server."""

    def __init__(self, target_port: int) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.target_port = target_port
        self.seen = bytearray()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        client, _ = self.listener.accept()
        server = socket.create_connection(("127.0.0.1", self.target_port))
        back = threading.Thread(target=self._pump, args=(server, client, None), daemon=True)
        back.start()
        self._pump(client, server, self.seen)
        back.join()
        client.close()
        server.close()

    @staticmethod
    def _pump(src: socket.socket, dst: socket.socket, record: bytearray | None) -> None:
        with contextlib.suppress(OSError):
            while data := src.recv(65536):
                if record is not None:
                    record += data
                dst.sendall(data)
        for sock in (src, dst):
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)

    def close(self) -> None:
        self.listener.close()
        self.thread.join(timeout=5)


def test_right_keys_deliver_an_encrypted_message(net: Net, keys: CurveKeys) -> None:
    auth = net.authenticator(keys)
    pull, endpoint = net.server(keys)
    tap = _Tap(int(endpoint.rsplit(":", 1)[1]))
    net.stack.callback(tap.close)
    push = net.socket(zmq.PUSH)
    secure_client(push, keys)
    watch = net.watch(push)
    push.connect(f"tcp://127.0.0.1:{tap.port}")
    watch.wait(5)
    push.send(PAYLOAD)
    assert pull.poll(5000)
    assert pull.recv() == PAYLOAD
    assert pull.curve_server
    assert pull.mechanism == zmq.CURVE
    assert push.mechanism == zmq.CURVE
    watch.check()
    assert auth.refused == []
    net.close()  # ends the relayed connection, so the tap has seen everything
    assert len(tap.seen) > len(PAYLOAD)
    assert PAYLOAD not in tap.seen  # on the wire only as ciphertext


def test_any_zap_domain_admits_the_rig_key(net: Net, keys: CurveKeys) -> None:
    net.authenticator(keys)
    pull = net.socket(zmq.PULL)
    pull.zap_domain = b"flowtact-stream"
    secure_server(pull, keys)
    port = pull.bind_to_random_port("tcp://127.0.0.1")
    push = net.socket(zmq.PUSH)
    secure_client(push, keys)
    push.connect(f"tcp://127.0.0.1:{port}")
    push.send(PAYLOAD)
    assert pull.poll(5000)
    assert pull.recv() == PAYLOAD


def test_another_keypair_is_refused_on_both_sides(net: Net, keys: CurveKeys, other_keys: CurveKeys) -> None:
    auth = net.authenticator(keys)
    pull, endpoint = net.server(keys)
    server_watch = net.watch(pull)
    push = net.socket(zmq.PUSH)
    # a host with its own `flowtact keys` run: its keypair, but the right server key
    push.curve_secretkey, push.curve_publickey = other_keys.secret, other_keys.public
    push.curve_serverkey = keys.public
    watch = net.watch(push)
    push.connect(endpoint)
    push.send(PAYLOAD)
    with pytest.raises(
        SecurityError, match=r"refused: the peer does not accept this key.*same `flowtact keys`"
    ):
        watch.wait(2)
    assert not pull.poll(200)
    with pytest.raises(SecurityError, match=f"refused a connection on {endpoint}"):
        server_watch.wait(2)
    assert auth.refused_count >= 1
    assert "refused a connection from 127.0.0.1: unknown CURVE key" in auth.refused[0]
    assert other_keys.public[:8].decode() in auth.refused[0]


def test_wrong_server_key_is_reported_by_the_client(net: Net, keys: CurveKeys, other_keys: CurveKeys) -> None:
    net.authenticator(keys)
    pull, endpoint = net.server(keys)
    push = net.socket(zmq.PUSH)
    push.curve_secretkey, push.curve_publickey = keys.secret, keys.public
    push.curve_serverkey = other_keys.public
    watch = net.watch(push)
    push.connect(endpoint)
    push.send(PAYLOAD)
    with pytest.raises(SecurityError, match=f"CURVE handshake with {endpoint} failed.*server key"):
        watch.wait(2)
    assert not pull.poll(200)


def test_plain_text_client_is_refused(net: Net, keys: CurveKeys) -> None:
    net.authenticator(keys)
    pull, endpoint = net.server(keys)
    push = net.socket(zmq.PUSH)
    watch = net.watch(push)
    push.connect(endpoint)
    push.send(PAYLOAD)
    with pytest.raises(SecurityError, match=r"requires CURVE encryption and this socket is plain text"):
        watch.wait(2)
    assert not pull.poll(200)


def test_curve_client_refuses_a_plain_text_server(net: Net, keys: CurveKeys) -> None:
    pull = net.socket(zmq.PULL)
    port = pull.bind_to_random_port("tcp://127.0.0.1")
    push = net.socket(zmq.PUSH)
    secure_client(push, keys)
    watch = net.watch(push)
    push.connect(f"tcp://127.0.0.1:{port}")
    push.send(PAYLOAD)
    with pytest.raises(SecurityError, match="the peer is a plain-text socket"):
        watch.wait(2)
    assert not pull.poll(200)


def test_no_peer_times_out_with_a_clear_message(net: Net, keys: CurveKeys) -> None:
    # a port that is held (so nothing else can listen on it, and no self-connect) but not listening
    holder = socket.socket()
    net.stack.callback(holder.close)
    holder.bind(("127.0.0.1", 0))
    port = holder.getsockname()[1]
    push = net.socket(zmq.PUSH)
    secure_client(push, keys)
    watch = net.watch(push)
    push.connect(f"tcp://127.0.0.1:{port}")
    watch.check()  # nothing failed yet
    with pytest.raises(SecurityError, match=r"no CURVE handshake with tcp://127\.0\.0\.1:\d+ within 0\.3 s"):
        watch.wait(0.3)


def test_a_curve_server_needs_an_authenticator(net: Net, keys: CurveKeys) -> None:
    pull = net.socket(zmq.PULL)
    with pytest.raises(SecurityError, match="needs a running Authenticator"):
        secure_server(pull, keys)
    assert not pull.curve_server
    with Authenticator(net.ctx, keys):
        secure_server(pull, keys)
    assert pull.curve_server
    other = net.socket(zmq.PULL)
    with pytest.raises(SecurityError, match="needs a running Authenticator"):
        secure_server(other, keys)  # stopped again


def test_one_authenticator_per_context(net: Net, keys: CurveKeys) -> None:
    first = net.authenticator(keys)
    with pytest.raises(SecurityError, match="already running"):
        Authenticator(net.ctx, keys).start()
    assert first.running
    net.close()
    assert not first.running
