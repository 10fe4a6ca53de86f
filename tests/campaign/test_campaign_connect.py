"""Where a campaign's Dask cluster listens and how it reaches an existing one (issue 44), through the
real CLI and real Dask processes (no mocks):

- a local cluster listens on 127.0.0.1 only, its dashboard included (psutil, during the run), and
  prints the dashboard's URL;
- ``--scheduler-file FILE`` from a real ``dask scheduler --scheduler-file`` with two ``dask worker``
  processes, and a ``tls://`` scheduler and worker with a self-signed certificate made here, the
  client's credentials from Dask's own configuration (``DASK_DISTRIBUTED__COMM__TLS__*``): the
  smoke campaign to complete rows;
- a scheduler that cannot be used (unreachable, an HTTP server, ``tls://`` without credentials, a
  scheduler file that is missing, not JSON or a folder): one line, exit 2, the folder not claimed.

The campaign is the smoke campaign with one random draw (2 samples x 2 arms x 2 s).
"""
from __future__ import annotations

import datetime
import ipaddress
import json
import shutil
import subprocess
import threading
import time
from http.server import BaseHTTPRequestHandler, HTTPServer
from pathlib import Path

import psutil
import pytest

from scenarios.campaign.execute import DASHBOARD_LINE
from support.paths import MODEL_ENV
from support.smoke_campaign import CLI, campaign_env, campaign_in_process
from test_campaign_dask import BIN, campaign_file, rows, stop, wait_for

LOOPBACK = {"127.0.0.1", "::1"}
#: Dask's connect timeout for the failure cases (its default, 30 s, only makes them slower; on
#: loopback a connection takes milliseconds, so 1 s is far above it).
CONNECT_TIMEOUT = "1s"


def _complete(out: Path) -> None:
    rs = rows(out)
    assert [(r["sample"], r["arm"]) for r in rs] == [(f"s{i:04d}", a) for i in range(2) for a in ("adaptive", "pd_only")]
    assert all(r["status"] == "complete" for r in rs), rs


def _listening(pid: int) -> set[tuple[str, int, int]]:
    """(address, port, pid) of every listening TCP socket of process ``pid`` and its descendants."""
    found = set()
    try:
        procs = [psutil.Process(pid), *psutil.Process(pid).children(recursive=True)]
    except psutil.NoSuchProcess:
        return found
    for p in procs:
        try:
            for c in p.net_connections(kind="tcp"):
                if c.status == psutil.CONN_LISTEN:
                    found.add((c.laddr.ip, c.laddr.port, p.pid))
        except (psutil.NoSuchProcess, psutil.ZombieProcess, psutil.AccessDenied):
            continue
    return found


# --------------------------------------------------------------------------- local cluster
def test_local_cluster_listens_on_loopback_only_and_prints_its_dashboard(tmp_path, built_fmu):
    out = tmp_path / "out"
    cli = subprocess.Popen(CLI + [campaign_file(tmp_path, 1), "--out", out, "--workers", "2", "--fmu", built_fmu,
                                  "--no-plots"],
                           env=campaign_env(tmp_path), cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen: set[tuple[str, int, int]] = set()
    try:
        while cli.poll() is None:
            seen |= _listening(cli.pid)
            time.sleep(0.2)
        stdout, stderr = cli.communicate(timeout=60)
    finally:
        stop(cli)
    assert cli.returncode == 0, stderr
    _complete(out)
    # the scheduler, its dashboard, and each of the 2 workers and their nannies: 6 sockets at least
    assert len({(ip, port) for ip, port, _ in seen}) >= 6, seen
    exposed = sorted(s for s in seen if s[0] not in LOOPBACK)
    assert exposed == [], f"listening beyond loopback: {exposed}"
    dashboard = [line for line in stderr.splitlines() if line.startswith(DASHBOARD_LINE)]
    assert len(dashboard) == 1 and dashboard[0].startswith("Dask dashboard: http://127.0.0.1:"), stderr
    port = int(dashboard[0].split(":")[-1].split("/")[0])
    assert any(p == port and ip in LOOPBACK for ip, p, _ in seen), (port, seen)


# --------------------------------------------------------------------------- existing schedulers
def _scheduler(tmp_path: Path, env: dict, *extra) -> tuple[subprocess.Popen, Path, str]:
    sched_file = tmp_path / "scheduler.json"
    proc = subprocess.Popen([BIN / "dask", "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                             "--scheduler-file", sched_file, *extra], env=env, cwd=tmp_path,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    address = wait_for(lambda: sched_file.is_file() and json.loads(sched_file.read_text() or "{}").get("address"),
                       "the scheduler file", 60)
    return proc, sched_file, address


def _worker(tmp_path: Path, env: dict, address: str, name: str, *extra) -> subprocess.Popen:
    return subprocess.Popen([BIN / "dask", "worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard",
                             "--local-directory", tmp_path / name, *extra], env=env, cwd=tmp_path,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def test_scheduler_file_with_two_worker_processes(tmp_path, built_fmu):
    env = campaign_env(tmp_path)
    procs = []
    try:
        sched, sched_file, address = _scheduler(tmp_path, env)
        procs.append(sched)
        procs += [_worker(tmp_path, env, address, f"worker{k}") for k in range(2)]
        campaign_file(tmp_path, 1)
        (tmp_path / "fmus").mkdir()
        shutil.copy(built_fmu, tmp_path / "fmus" / Path(built_fmu).name)
        # every path relative to the working folder: the campaign file, --out, the scheduler file, --fmu
        r = subprocess.run(CLI + ["smoke1.toml", "--out", "out", "--scheduler-file", "scheduler.json",
                                  "--fmu", f"fmus/{Path(built_fmu).name}", "--no-plots"],
                           capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        _complete(tmp_path / "out")
        # the scheduler the file names is the one with both workers
        from distributed import Client

        with Client(scheduler_file=str(sched_file), timeout="10s") as client:
            assert len(client.scheduler_info()["workers"]) == 2
    finally:
        for p in reversed(procs):
            stop(p)


def _self_signed(folder: Path) -> tuple[Path, Path]:
    """A key and a self-signed certificate for 127.0.0.1 (its own CA), PEM files."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "cassie-avr test")])
    now = datetime.datetime.now(datetime.timezone.utc)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(hours=2))
            .add_extension(x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), False)
            .add_extension(x509.BasicConstraints(ca=True, path_length=None), True)
            .sign(key, hashes.SHA256()))
    key_file, cert_file = folder / "key.pem", folder / "cert.pem"
    key_file.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    cert_file.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    return key_file, cert_file


def test_tls_scheduler_with_dasks_security_configuration(tmp_path, built_fmu):
    key, cert = _self_signed(tmp_path)
    tls = ["--tls-ca-file", cert, "--tls-cert", cert, "--tls-key", key]
    env = campaign_env(tmp_path)
    procs = []
    try:
        sched, _, address = _scheduler(tmp_path, env, "--protocol", "tls", *tls)
        procs.append(sched)
        assert address.startswith("tls://127.0.0.1:")
        procs.append(_worker(tmp_path, env, address, "worker", *tls))
        out = tmp_path / "out"
        client_env = {**env, "DASK_DISTRIBUTED__COMM__TLS__CA_FILE": str(cert),
                      "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT": str(cert),
                      "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY": str(key)}
        r = subprocess.run(CLI + [str(a) for a in (campaign_file(tmp_path, 1), "--out", out, "--scheduler", address,
                                                   "--fmu", built_fmu, "--no-plots")],
                           capture_output=True, text=True, timeout=300, env=client_env, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        _complete(out)
        # the same scheduler without the credentials: one line naming the TLS configuration, exit 2
        out2 = tmp_path / "out2"
        r = subprocess.run(CLI + [str(a) for a in (campaign_file(tmp_path, 1), "--out", out2, "--scheduler", address,
                                                   "--fmu", built_fmu)],
                           capture_output=True, text=True, timeout=120, env=env, cwd=tmp_path)
        assert r.returncode == 2 and len(r.stderr.splitlines()) == 1 and "TLS configuration" in r.stderr, r.stderr
        assert not out2.exists()
    finally:
        for p in reversed(procs):
            stop(p)


# --------------------------------------------------------------------------- schedulers that cannot be used
class _Http(BaseHTTPRequestHandler):
    def do_GET(self):  # noqa: N802 - http.server's name
        self.send_response(200)
        self.end_headers()

    def log_message(self, *args):
        pass


@pytest.fixture
def http_server():
    server = HTTPServer(("127.0.0.1", 0), _Http)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_schedulers_that_cannot_be_used_are_one_line_and_exit_2(tmp_path, built_fmu, http_server, capsys,
                                                                 monkeypatch):
    import dask

    monkeypatch.setenv("MENAGERIE_ROOT", MODEL_ENV["MENAGERIE_ROOT"])  # absolute: the test moves to tmp_path
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder").mkdir()
    (tmp_path / "notjson.json").write_text("{not json")
    (tmp_path / "noaddress.json").write_text('{"type": "Scheduler"}')
    cases = [
        (["--scheduler", f"tcp://127.0.0.1:{_free_port()}"], "cannot connect to a Dask scheduler at tcp://127.0.0.1:"),
        (["--scheduler", f"tcp://{http_server}"], "gave no Dask answer"),
        (["--scheduler", f"tls://{http_server}"], "TLS configuration"),
        (["--scheduler", f"http://{http_server}"], "unknown address scheme 'http'"),
        (["--scheduler-file", "missing.json"], "--scheduler-file missing.json: cannot read: No such file"),
        (["--scheduler-file", "notjson.json"], "--scheduler-file notjson.json: not a Dask scheduler file"),
        (["--scheduler-file", "noaddress.json"], "--scheduler-file noaddress.json: not a Dask scheduler file"),
        (["--scheduler-file", "folder"], "--scheduler-file folder: is a folder, not a Dask scheduler file"),
        (["--workers", "1", "--dashboard-address", "0.0.0.0"], "--dashboard-address 0.0.0.0: must be HOST:PORT"),
        (["--scheduler", "tcp://127.0.0.1:1", "--dashboard-address", "0.0.0.0:1"], "only for the local cluster"),
    ]
    smoke = campaign_file(tmp_path, 1)
    with dask.config.set({"distributed.comm.timeouts.connect": CONNECT_TIMEOUT}):
        for extra, message in cases:
            t0 = time.monotonic()
            rc, out, err = campaign_in_process(capsys, smoke, "--out", "out", "--fmu", built_fmu, *extra)
            assert rc == 2 and message in err and "Traceback" not in err, (extra, err)
            assert len(err.strip().splitlines()) == 1 and out == "", (extra, err)
            assert not (tmp_path / "out").exists(), extra
            assert time.monotonic() - t0 < 30, extra  # twice the connect timeout at most, plus the checks
