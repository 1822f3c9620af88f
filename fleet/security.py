"""The fleet bus secured with Zenoh's own features: mutual TLS and access control.

Every process holds a certificate from the fleet's CA (deploy/tls/make-certs.sh; its
common name is ``carN`` for car N, ``operator`` for trustfg go / dashboard / record). With
mutual TLS a session without a certificate from that CA cannot connect at all: it can
neither receive nor publish.

Access control (Zenoh's ``access_control`` block, default deny) is enforced by every
receiving process on what arrives from each authenticated peer (ingress), so that:

* car N may put, and declare liveliness tokens and the queryables of its advanced
  publishers, only under ``trustfg/F/N/**`` -- a car cannot speak for another: what car 2
  publishes on car 1's keys reaches nobody;
* only the operator may put the start message (``trustfg/F/start``);
* everyone may subscribe and query (read) anything of the fleet.

What a process sends is not restricted here (egress is allowed): each receiver guards
itself.

    trustfg secure-config --fleet F --cars 1 2 3 4 --certs DIR --identity car1 --out car1.json5

writes the JSON5 to name in ``[bus] zenoh_config`` (endpoints must then be ``tls/...``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from . import keys

ALL_MESSAGES = ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
                "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"]
READ = ["declare_subscriber", "declare_liveliness_subscriber", "query", "liveliness_query"]
WRITE = ["put", "delete", "declare_queryable", "reply"]


def certificate_names(certs: Path, identity: str) -> dict[str, str]:
    """Paths of the CA certificate and of this identity's key and certificate."""
    paths = {"ca": certs / "ca.pem", "key": certs / f"{identity}.key", "cert": certs / f"{identity}.pem"}
    missing = [str(p) for p in paths.values() if not p.exists()]
    if missing:
        raise FileNotFoundError(f"missing TLS files: {', '.join(missing)} (deploy/tls/make-certs.sh makes them)")
    return {k: str(p.resolve()) for k, p in paths.items()}


def access_control(fleet: str, cars: list[int]) -> dict:
    everything = keys.fleet_tree(fleet)
    rules = [
        {"id": "send-anything", "permission": "allow", "flows": ["egress"], "messages": ALL_MESSAGES,
         "key_exprs": ["**", "**/@adv/**"]},
        {"id": "read-the-fleet", "permission": "allow", "flows": ["ingress"], "messages": READ,
         "key_exprs": everything},
        # Advanced subscribers announce themselves with tokens under @adv of what they read.
        {"id": "subscriber-tokens", "permission": "allow", "flows": ["ingress"], "messages": ["liveliness_token"],
         "key_exprs": everything[1:]},
        {"id": "operator-start", "permission": "allow", "flows": ["ingress"], "messages": WRITE + ["liveliness_token"],
         "key_exprs": keys.fleet_key_tree(fleet, keys.START)},
    ]
    subjects = [{"id": "operator", "cert_common_names": ["operator"]}]
    policies = [{"id": "operator", "rules": ["send-anything", "read-the-fleet", "subscriber-tokens", "operator-start"],
                 "subjects": ["operator"]}]
    for car in cars:
        rules.append({"id": f"car{car}-own-keys", "permission": "allow", "flows": ["ingress"],
                      "messages": WRITE + ["liveliness_token"], "key_exprs": keys.car_tree(fleet, car)})
        subjects.append({"id": f"car{car}", "cert_common_names": [f"car{car}"]})
        policies.append({"id": f"car{car}", "rules": ["send-anything", "read-the-fleet", "subscriber-tokens",
                                                       f"car{car}-own-keys"], "subjects": [f"car{car}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def secure_config(fleet: str, cars: list[int], certs: Path, identity: str) -> dict:
    """The Zenoh config (as a dict) for one process: its TLS identity and the fleet's ACL."""
    paths = certificate_names(certs, identity)
    tls = {"root_ca_certificate": paths["ca"], "listen_private_key": paths["key"], "listen_certificate": paths["cert"],
           "connect_private_key": paths["key"], "connect_certificate": paths["cert"], "enable_mtls": True,
           "verify_name_on_connect": False}
    return {"transport": {"link": {"tls": tls}}, "access_control": access_control(fleet, cars)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="trustfg secure-config", description=__doc__.split("\n")[0])
    parser.add_argument("--fleet", required=True)
    parser.add_argument("--cars", type=int, nargs="+", required=True)
    parser.add_argument("--certs", type=Path, required=True, help="folder made by deploy/tls/make-certs.sh")
    parser.add_argument("--identity", required=True, help="carN or operator")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    try:
        config = secure_config(args.fleet, args.cars, args.certs, args.identity)
    except FileNotFoundError as exc:
        print(f"trustfg secure-config: {exc}", file=sys.stderr)
        return 2
    args.out.write_text(json.dumps(config, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0
