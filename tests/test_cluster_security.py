"""A Dask cluster that only lets in who it should (pipeline.distributed): the local cluster
listens on loopback only, a plain-TCP scheduler on another machine is refused before anything
connects, and a fit runs over TLS with certificates made here. No traffic leaves 127.0.0.1."""
import datetime
import ipaddress

import psutil
import pytest

from invface.errors import InvfaceError
from invface.pipeline import distributed as dist


def _listening(proc):
    conns = proc.net_connections(kind="inet") if hasattr(proc, "net_connections") else proc.connections(kind="inet")
    return [c.laddr for c in conns if c.status == psutil.CONN_LISTEN]


def test_local_cluster_listens_on_loopback_only():
    client, cluster = dist._client(2, None)
    try:
        assert len(client.scheduler_info()["workers"]) == 2
        me = psutil.Process()
        addrs = [a for p in [me, *me.children(recursive=True)] for a in _listening(p)]
        assert len(addrs) >= 3, addrs                          # the scheduler, workers and nannies
        assert all(ipaddress.ip_address(a.ip).is_loopback for a in addrs), addrs
    finally:
        client.close()
        cluster.close()


def test_plain_tcp_beyond_loopback_is_refused_before_any_connection(monkeypatch, tmp_path):
    import distributed
    made = []
    monkeypatch.setattr(distributed, "Client", lambda *a, **k: made.append(a))
    with pytest.raises(InvfaceError, match=r"tcp://10\.1\.2\.3:8786: plain TCP to another machine is refused.*pickled"):
        dist.scheduler_security("tcp://10.1.2.3:8786")
    with pytest.raises(InvfaceError, match="refused"):
        dist.fit_sequence_distributed(None, [0, 1], None, tmp_path, scheduler="10.1.2.3:8786")
    from invface.cli import main
    assert main(["fit-plate", str(tmp_path / "no-such.png"), "--scheduler", "tcp://192.168.7.7:8786"]) == 2
    assert made == []                                           # nothing tried to connect
    assert dist.scheduler_security("tcp://127.0.0.1:8786") is None
    assert dist.scheduler_security("localhost:8786") is None and dist.scheduler_security("tcp://[::1]:8786") is None
    assert dist.scheduler_security("tcp://10.1.2.3:8786", insecure=True) is None
    with pytest.raises(InvfaceError, match="needs certificates"):
        dist.scheduler_security("tls://10.1.2.3:8786")
    (tmp_path / "ca.pem").write_text("x")
    with pytest.raises(InvfaceError, match="missing --tls-cert, --tls-key"):
        dist.scheduler_security("tls://10.1.2.3:8786", tls_ca=tmp_path / "ca.pem")
    with pytest.raises(InvfaceError, match="--tls-key .*nope.pem: no such file"):
        dist.scheduler_security("tls://10.1.2.3:8786", tmp_path / "ca.pem", tmp_path / "ca.pem", tmp_path / "nope.pem")
    with pytest.raises(InvfaceError, match="use tls://"):
        dist.scheduler_security("ws://127.0.0.1:8786")


def _certificates(folder):
    """A CA and one certificate it signed for 127.0.0.1 (scheduler, worker and client share it)."""
    pytest.importorskip("cryptography")
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID
    now = datetime.datetime.now(datetime.timezone.utc)
    span = dict(not_valid_before=now - datetime.timedelta(days=1), not_valid_after=now + datetime.timedelta(days=1))
    ca_key, key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "invface test CA")])
    ca = (x509.CertificateBuilder(subject_name=ca_name, issuer_name=ca_name, public_key=ca_key.public_key(),
                                  serial_number=x509.random_serial_number(), **span)
          .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True).sign(ca_key, hashes.SHA256()))
    cert = (x509.CertificateBuilder(subject_name=x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "127.0.0.1")]),
                                    issuer_name=ca_name, public_key=key.public_key(),
                                    serial_number=x509.random_serial_number(), **span)
            .add_extension(x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address("127.0.0.1")),
                                                        x509.DNSName("localhost")]), critical=False)
            .sign(ca_key, hashes.SHA256()))
    pem = serialization.Encoding.PEM
    (folder / "ca.pem").write_bytes(ca.public_bytes(pem))
    (folder / "cert.pem").write_bytes(cert.public_bytes(pem))
    (folder / "key.pem").write_bytes(key.private_bytes(pem, serialization.PrivateFormat.PKCS8,
                                                       serialization.NoEncryption()))
    return folder / "ca.pem", folder / "cert.pem", folder / "key.pem"


def test_a_fit_runs_over_tls_and_the_same_address_without_tls_is_refused(small_expressive_model, tmp_path,
                                                                         monkeypatch):
    from distributed import LocalCluster, Security

    from invface.fit.calibrate import Calibration
    from invface.fit.samples import write_sample_clip
    from invface.pipeline.clips import open_clip
    from invface.render.synthetic import skin_albedo, studio_light
    ca, cert, key = _certificates(tmp_path)
    files = dict(tls_ca_file=str(ca), require_encryption=True)
    for role in ("scheduler", "worker", "client"):
        files.update({f"tls_{role}_cert": str(cert), f"tls_{role}_key": str(key)})
    m = small_expressive_model
    frames, _ = write_sample_clip(m, tmp_path / "clip", n=2, size=(160, 120), video=False)
    cal = Calibration(gamma=studio_light(), albedo=skin_albedo(m))
    with LocalCluster(n_workers=1, processes=False, threads_per_worker=1, host="127.0.0.1", protocol="tls://",
                      security=Security(**files), dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tls://127.0.0.1:")
        rows = dist.fit_sequence_distributed(m, open_clip(frames), cal, tmp_path / "out", scheduler=address,
                                             security=dist.scheduler_security(address, ca, cert, key),
                                             shading=False, iterations=0)
        assert [sorted(r["kinds"]) for r in rows] == [["blendshape"], ["blendshape"]]
        monkeypatch.setattr(dist, "CONNECT_TIMEOUT", "3s")
        with pytest.raises(InvfaceError, match="no Dask scheduler answers there"):
            dist._client(None, address.replace("tls://", "tcp://"))
