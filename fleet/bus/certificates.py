"""The fleet's TLS files for the bus's mutual TLS: their names, and keys and certificates
made with the ``openssl`` command.

A name says what a file is: ``ca.tls.crt`` (the fleet's CA), ``car3.tls.key`` and
``car3.tls.crt`` (car 3's private key and certificate, common name ``car3``),
``operator.tls.key`` and ``operator.tls.crt``. A TLS key is a PEM file; it never shares a
name with a car-link key (``car3.link.key``, bridge.carlink.keys). Keys are EC P-256;
every certificate also names 127.0.0.1 and localhost, for fleets on one machine.
``trustfg keys`` (fleet.operator.keys) makes them; ``trustfg secure-config`` reads them.
"""

from __future__ import annotations

import secrets
import subprocess
import tempfile
from pathlib import Path

CA = "ca"
"""The CA's name in its files (``ca.tls.crt``, ``ca.tls.key``)."""

CA_COMMON_NAME = "trustfg fleet CA"
CA_DAYS = 3650
"""The CA is made once and reused for every car added later: ten years."""

MEMBER_DAYS = 825
"""A member's certificate; ``trustfg keys --rotate`` issues a new one."""

_REQUEST = "[req]\ndistinguished_name = dn\nprompt = no\n[dn]\nCN = {name}\n"
_CA_EXTENSIONS = ("[ca]\nbasicConstraints = critical,CA:TRUE\nkeyUsage = critical,keyCertSign,cRLSign\n"
                  "subjectKeyIdentifier = hash\n")
_MEMBER_EXTENSIONS = ("basicConstraints = CA:FALSE\nextendedKeyUsage = serverAuth,clientAuth\n"
                      "subjectAltName = DNS:{name},DNS:localhost,IP:127.0.0.1\n")


class CertificateError(Exception):
    """openssl is missing, or refused what it was asked (its message attached)."""


def key_name(identity: str) -> str:
    return f"{identity}.tls.key"


def cert_name(identity: str) -> str:
    return f"{identity}.tls.crt"


def _openssl(*args: str) -> bytes:
    try:
        done = subprocess.run(["openssl", *args], capture_output=True, timeout=60)
    except FileNotFoundError:
        raise CertificateError("the openssl command is not installed (apt install openssl)") from None
    if done.returncode != 0:
        raise CertificateError(f"openssl {args[0]}: {done.stderr.decode(errors='replace').strip()}")
    return done.stdout


def new_key() -> bytes:
    """A new private key, PEM (PKCS#8: ``-----BEGIN PRIVATE KEY-----``)."""
    return _openssl("genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256")


def new_ca(ca_key: Path) -> bytes:
    """The fleet's self-signed CA certificate for the key in ``ca_key``, PEM."""
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "ca.cnf"
        config.write_text(_REQUEST.format(name=CA_COMMON_NAME) + _CA_EXTENSIONS)
        return _openssl("req", "-x509", "-new", "-key", str(ca_key), "-config", str(config), "-extensions", "ca",
                        "-days", str(CA_DAYS), "-sha256")


def issue(identity: str, key: Path, ca_cert: Path, ca_key: Path) -> bytes:
    """A certificate for ``identity`` (its common name) and the key in ``key``, signed by
    the CA, PEM."""
    with tempfile.TemporaryDirectory() as tmp:
        request, extensions = Path(tmp) / "request.cnf", Path(tmp) / "extensions.cnf"
        request.write_text(_REQUEST.format(name=identity))
        extensions.write_text(_MEMBER_EXTENSIONS.format(name=identity))
        csr = Path(tmp) / "member.csr"
        csr.write_bytes(_openssl("req", "-new", "-key", str(key), "-config", str(request)))
        return _openssl("x509", "-req", "-in", str(csr), "-CA", str(ca_cert), "-CAkey", str(ca_key),
                        "-set_serial", f"0x{secrets.randbits(120):030x}", "-days", str(MEMBER_DAYS), "-sha256",
                        "-extfile", str(extensions))


def problem(cert: Path, key: Path, ca_cert: Path) -> str | None:
    """Why ``cert`` (with ``key``) cannot serve in this fleet -- not signed by the CA,
    expired, or not the certificate of that key -- or None when it can."""
    try:
        _openssl("verify", "-CAfile", str(ca_cert), str(cert))
    except CertificateError as exc:
        reasons = [line.split("lookup: ", 1)[1] for line in str(exc).splitlines() if "lookup: " in line]
        reason = reasons[0] if reasons else str(exc)
        if "unable to get local issuer" in reason:
            reason = "signed by another CA"
        return f"it does not verify against {ca_cert.name}: {reason}"
    if public_key(cert) != _openssl("pkey", "-in", str(key), "-pubout"):
        return f"it is not the certificate of {key.name}"
    return None


def public_key(cert: Path) -> bytes:
    return _openssl("x509", "-in", str(cert), "-noout", "-pubkey")


def ca_matches(ca_cert: Path, ca_key: Path) -> bool:
    """Whether ``ca_key`` is the key of ``ca_cert``."""
    return public_key(ca_cert) == _openssl("pkey", "-in", str(ca_key), "-pubout")
