"""The team's certificates: one certificate authority and a certificate per identity.

Every process of a secured team opens its Zenoh session over mutual TLS
(:class:`~agent.platform.zenoh_session.ZenohSettings` ``root_ca``, ``certificate``,
``private_key``): each side shows a certificate signed by the team's CA, and the router's access
control (:mod:`agent.security.access_control`) knows each process by its certificate's Common Name,
its
*identity*:

- ``router``: the Zenoh router,
- ``robot-<i>``: robot *i*'s computer (its agent and its AGV bridge),
- ``plant``: the simulator standing in for the robots (bench runs),
- ``operator``: whoever may stop a run (the launcher),
- ``dashboard``: the displays (they only listen).

:func:`make_certificates` writes, in one folder: ``ca.pem`` and ``ca-key.pem`` (the CA's
private key: it stays where certificates are made, never on a robot), and per identity
``<identity>.pem`` and ``<identity>-key.pem``. Private keys are written with mode 0600.
Nothing is overwritten without ``force``. Keys are ECDSA on P-256, signed with SHA-256 (what
every TLS library accepts, rustls included).
"""

from __future__ import annotations

import datetime
import ipaddress
import os
import re
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from agent.platform.config import MAX_ROBOTS

CA_CERT = "ca.pem"
CA_KEY = "ca-key.pem"
CA_NAME = "Heft team CA"
ROLES = ("router", "plant", "operator", "dashboard")
"""The identities beside the robots' ``robot-<i>``."""
DEFAULT_HOSTS = ("localhost", "127.0.0.1")
DEFAULT_DAYS = 825
"""How long a certificate is valid by default (the longest browsers accept for a server)."""
MAX_DAYS = 36_500
CLOCK_SKEW = datetime.timedelta(minutes=5)
"""Certificates are valid from this long before they are made: a host whose clock is a little
behind still accepts them."""
_ROBOT = re.compile(r"^robot-([1-9]\d{0,2})$")
_DNS_LABEL = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")


class CertificateError(ValueError):
    """Certificates cannot be made as asked: ``str()`` is one line naming the file or value."""


def robot_identity(robot: int) -> str:
    return f"robot-{robot}"


def team_identities(robots: int) -> list[str]:
    """The identities of a team of ``robots`` robots: the router, every robot, the plant, the
    operator and the dashboard."""
    if isinstance(robots, bool) or not isinstance(robots, int) or not 1 <= robots <= MAX_ROBOTS:
        raise CertificateError(f"robots: expected 1 to {MAX_ROBOTS}, got {robots!r}")
    return ["router", *(robot_identity(i) for i in range(1, robots + 1)), *ROLES[1:]]


def check_identity(name: str) -> str:
    """``name`` if it is an identity the access control knows (:data:`ROLES`, ``robot-<i>``)."""
    robot = _ROBOT.match(name)
    if name in ROLES or (robot and int(robot[1]) <= MAX_ROBOTS):
        return name
    raise CertificateError(
        f"identity {name!r}: expected one of {', '.join(ROLES)} or robot-<i> (1 to {MAX_ROBOTS})"
    )


def check_host(host: str) -> str:
    """``host`` if it is an IP address or a DNS name (what a certificate's subjectAltName
    holds)."""
    try:
        ipaddress.ip_address(host)
        return host
    except ValueError:
        pass
    labels = host.rstrip(".").split(".")
    if len(host) <= 253 and labels != [""] and all(_DNS_LABEL.match(label) for label in labels):
        return host
    raise CertificateError(f"host {host!r}: expected an IP address or a DNS name")


@dataclass(frozen=True)
class Made:
    """What :func:`make_certificates` did: the files it wrote, and whether it made the CA."""

    files: tuple[Path, ...]
    new_ca: bool


def make_certificates(
    directory: Path | str,
    identities: Iterable[str],
    hosts: Sequence[str] = DEFAULT_HOSTS,
    days: int = DEFAULT_DAYS,
    force: bool = False,
    new_ca: bool = True,
) -> Made:
    """Write the certificates of ``identities`` into ``directory`` (created, mode 0700).

    With ``new_ca`` a new CA is made first (refused if one is there, unless ``force``: then
    every certificate it signed must be made again). Without it, the CA already in
    ``directory`` signs them (refused if there is none). An identity's existing files are
    replaced only with ``force``. Every certificate names ``hosts`` in its subjectAltName: the
    router's must hold the name or address its clients connect to.

    :class:`CertificateError` (one line) before anything is written if something is wrong.
    """
    folder = Path(directory)
    names = [check_identity(name) for name in identities]
    if not names:
        raise CertificateError("no identity to make a certificate for")
    if len(set(names)) != len(names):
        raise CertificateError(f"identities: each once, got {', '.join(names)}")
    hosts = [check_host(host) for host in hosts]
    if not hosts:
        raise CertificateError("hosts: at least one name or address for subjectAltName")
    if isinstance(days, bool) or not isinstance(days, int) or not 1 <= days <= MAX_DAYS:
        raise CertificateError(f"days: expected 1 to {MAX_DAYS}, got {days!r}")
    if folder.exists() and not folder.is_dir():
        raise CertificateError(f"{folder}: not a folder")

    ca_files = [folder / CA_CERT, folder / CA_KEY]
    if new_ca:
        there = [path for path in ca_files if path.exists()]
        if there and not force:
            raise CertificateError(
                f"{there[0]}: a CA is already there; --force replaces it (and so every"
                " certificate it signed), --identity NAME adds one signed by it"
            )
    else:
        missing = [path for path in ca_files if not path.is_file()]
        if missing:
            raise CertificateError(
                f"{missing[0]}: no CA there to sign with; make the team's first (--robots N)"
            )
    if not force:
        for name in names:
            for path in (folder / f"{name}.pem", folder / f"{name}-key.pem"):
                if path.exists():
                    raise CertificateError(f"{path}: already there; --force replaces it")

    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    except OSError as err:
        raise CertificateError(f"{folder}: cannot create ({err.strerror or err})") from None
    now = datetime.datetime.now(datetime.UTC)
    written: list[Path] = []
    if new_ca:
        ca_key, ca_cert = _new_ca(now, days)
        written.append(_write(folder / CA_KEY, _key_pem(ca_key), 0o600, force))
        written.append(_write(folder / CA_CERT, _cert_pem(ca_cert), 0o644, force))
    else:
        ca_key, ca_cert = _load_ca(folder)
    for name in names:
        key, cert = _new_leaf(name, hosts, ca_key, ca_cert, now, days)
        written.append(_write(folder / f"{name}-key.pem", _key_pem(key), 0o600, force))
        written.append(_write(folder / f"{name}.pem", _cert_pem(cert), 0o644, force))
    return Made(tuple(written), new_ca)


# ------------------------------------------------------------------------------ X.509
def _new_key():
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _name(common_name: str):
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    return x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "Heft"),
            x509.NameAttribute(NameOID.COMMON_NAME, common_name),
        ]
    )


def _new_ca(now: datetime.datetime, days: int):
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    key = _new_key()
    public = key.public_key()
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(CA_NAME))
        .issuer_name(_name(CA_NAME))
        .public_key(public)
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - CLOCK_SKEW)
        .not_valid_after(now + datetime.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(_key_usage(signs_certificates=True), critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(public), critical=False)
        .sign(key, hashes.SHA256())
    )
    return key, cert


def _key_usage(signs_certificates: bool):
    """Digital signatures (TLS 1.3 with ECDSA keys), and for the CA, signing certificates and
    revocation lists."""
    from cryptography import x509

    return x509.KeyUsage(
        digital_signature=True,
        content_commitment=False,
        key_encipherment=False,
        data_encipherment=False,
        key_agreement=False,
        key_cert_sign=signs_certificates,
        crl_sign=signs_certificates,
        encipher_only=False,
        decipher_only=False,
    )


def _san(hosts: Sequence[str]):
    from cryptography import x509

    entries: list[x509.GeneralName] = []
    for host in hosts:
        try:
            entries.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            entries.append(x509.DNSName(host))
    return x509.SubjectAlternativeName(entries)


def _new_leaf(name: str, hosts: Sequence[str], ca_key, ca_cert, now, days: int):
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.x509.oid import ExtendedKeyUsageOID

    key = _new_key()
    public = key.public_key()
    # Never valid past the CA that signs it.
    not_after = min(now + datetime.timedelta(days=days), ca_cert.not_valid_after_utc)
    ca_ski = ca_cert.extensions.get_extension_for_class(x509.SubjectKeyIdentifier).value
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(name))
        .issuer_name(ca_cert.subject)
        .public_key(public)
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - CLOCK_SKEW)
        .not_valid_after(not_after)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(_key_usage(signs_certificates=False), critical=True)
        # Every identity both accepts sessions and opens them (a router may connect to
        # another; a client's certificate is checked by the router under mutual TLS).
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .add_extension(_san(hosts), critical=False)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(public), critical=False)
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_subject_key_identifier(ca_ski),
            critical=False,
        )
        .sign(ca_key, hashes.SHA256())
    )
    return key, cert


def _load_ca(folder: Path):
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    cert_path, key_path = folder / CA_CERT, folder / CA_KEY
    try:
        cert = x509.load_pem_x509_certificate(cert_path.read_bytes())
    except (OSError, ValueError) as err:
        raise CertificateError(f"{cert_path}: not a readable PEM certificate ({err})") from None
    try:
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    except (OSError, ValueError, TypeError) as err:
        raise CertificateError(f"{key_path}: not a readable PEM private key ({err})") from None
    if key.public_key().public_bytes(
        serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    ) != cert.public_key().public_bytes(
        serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    ):
        raise CertificateError(f"{key_path}: not the private key of {cert_path}")
    return key, cert


def _key_pem(key) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def _cert_pem(cert) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return cert.public_bytes(serialization.Encoding.PEM)


def _write(path: Path, data: bytes, mode: int, replace: bool) -> Path:
    """Write ``path`` whole, with ``mode`` from the start (a key is never readable by others,
    not even for a moment); an existing file is replaced only if ``replace``."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")  # mode 0600
    try:
        with os.fdopen(fd, "wb") as stream:
            os.fchmod(stream.fileno(), mode)
            stream.write(data)
            stream.flush()
            os.fsync(stream.fileno())
        if replace:
            os.replace(tmp, path)
        else:
            os.link(tmp, path)  # fails if something appeared there meanwhile
            os.unlink(tmp)
    except FileExistsError:
        os.unlink(tmp)
        raise CertificateError(f"{path}: already there; --force replaces it") from None
    except OSError as err:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise CertificateError(f"{path}: cannot write ({err.strerror or err})") from None
    return path
