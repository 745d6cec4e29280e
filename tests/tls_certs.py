"""Throw-away X.509 material for the TLS tests, made with ``cryptography``: a CA, a server
certificate for 127.0.0.1/localhost (valid, expired, or for another host name), a client
certificate signed by the same CA, and a second, unrelated CA (the "wrong CA").

Keys are ECDSA P-256 (fast to make); every file is PEM, written by ``make_pki(directory)``.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

_DAY = dt.timedelta(days=1)


@dataclass(frozen=True)
class Pki:
    """Paths of the PEM files ``make_pki`` wrote."""

    ca: Path  # the CA that signed everything below
    other_ca: Path  # an unrelated CA: the wrong --ca
    server_cert: Path  # CN/SAN 127.0.0.1 and localhost, valid now
    server_key: Path
    expired_cert: Path  # same names and key, expired yesterday
    wrong_host_cert: Path  # SAN broker.example only (a host name mismatch on 127.0.0.1)
    client_cert: Path  # signed by ca, for TLS client authentication
    client_key: Path


def _name(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _key() -> ec.EllipticCurvePrivateKey:
    return ec.generate_private_key(ec.SECP256R1())


def _write_key(path: Path, key: ec.EllipticCurvePrivateKey) -> Path:
    path.write_bytes(key.private_bytes(serialization.Encoding.PEM,
                                       serialization.PrivateFormat.PKCS8,
                                       serialization.NoEncryption()))
    path.chmod(0o600)
    return path


def _write_cert(path: Path, cert: x509.Certificate) -> Path:
    path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    return path


def _ca(common_name: str) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    key = _key()
    now = dt.datetime.now(dt.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(common_name)).issuer_name(_name(common_name))
        .public_key(key.public_key()).serial_number(x509.random_serial_number())
        .not_valid_before(now - _DAY).not_valid_after(now + 30 * _DAY)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                     content_commitment=False, key_encipherment=False,
                                     data_encipherment=False, key_agreement=False,
                                     encipher_only=False, decipher_only=False), critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()),
                       critical=False)
        .sign(key, hashes.SHA256())
    )
    return cert, key


def _leaf(
    ca: tuple[x509.Certificate, ec.EllipticCurvePrivateKey],
    key: ec.EllipticCurvePrivateKey,
    common_name: str,
    *,
    names: list[x509.GeneralName],
    usage: x509.ObjectIdentifier,
    valid: tuple[dt.datetime, dt.datetime],
) -> x509.Certificate:
    ca_cert, ca_key = ca
    builder = (
        x509.CertificateBuilder()
        .subject_name(_name(common_name)).issuer_name(ca_cert.subject)
        .public_key(key.public_key()).serial_number(x509.random_serial_number())
        .not_valid_before(valid[0]).not_valid_after(valid[1])
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()),
                       critical=False)
    )
    if names:
        builder = builder.add_extension(x509.SubjectAlternativeName(names), critical=False)
    return builder.sign(ca_key, hashes.SHA256())


def make_pki(directory: Path) -> Pki:
    """Write a CA, server/client certificates and the bad variants into ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    ca, other = _ca("odocan test CA"), _ca("someone else's CA")
    now = dt.datetime.now(dt.UTC)
    valid, expired = (now - _DAY, now + 30 * _DAY), (now - 30 * _DAY, now - _DAY)
    server_key = _key()
    local = [x509.IPAddress(ipaddress.ip_address("127.0.0.1")), x509.DNSName("localhost")]
    server = ExtendedKeyUsageOID.SERVER_AUTH
    client_key = _key()
    return Pki(
        ca=_write_cert(directory / "ca.pem", ca[0]),
        other_ca=_write_cert(directory / "other-ca.pem", other[0]),
        server_cert=_write_cert(directory / "server.pem", _leaf(
            ca, server_key, "127.0.0.1", names=local, usage=server, valid=valid)),
        server_key=_write_key(directory / "server.key", server_key),
        expired_cert=_write_cert(directory / "expired.pem", _leaf(
            ca, server_key, "127.0.0.1", names=local, usage=server, valid=expired)),
        wrong_host_cert=_write_cert(directory / "wrong-host.pem", _leaf(
            ca, server_key, "broker.example", names=[x509.DNSName("broker.example")],
            usage=server, valid=valid)),
        client_cert=_write_cert(directory / "client.pem", _leaf(
            ca, client_key, "robot001", names=[], usage=ExtendedKeyUsageOID.CLIENT_AUTH,
            valid=valid)),
        client_key=_write_key(directory / "client.key", client_key),
    )
