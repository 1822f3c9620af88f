"""trustfg config: the reference of every key a scenario file may set, or the effective
configuration of a run as TOML.

'trustfg config reference' prints the reference (docs/configuration.md is this output);
'trustfg config show --scenario FILE|NAME' prints every key a run of that scenario uses:
trustfg's defaults, then the file.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .checks import ConfigError


class _Parser(argparse.ArgumentParser):
    """A usage error is one line and exit status 2, as with every trustfg command (this
    layer does not import fleet.program's parser); an option is named whole."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: {message} (see --help)\n")


def main(argv: list[str] | None = None) -> int:
    parser = _Parser(prog="trustfg config", description=__doc__.split("\n\n")[0], allow_abbrev=False)
    sub = parser.add_subparsers(dest="action", required=True)
    text = "every table and key of a scenario file: type, unit, default and meaning, as Markdown."
    reference = sub.add_parser("reference", allow_abbrev=False, help=text, description=text[0].upper() + text[1:])
    reference.add_argument("--out", type=Path, default=None, metavar="FILE",
                           help="write the page to FILE, e.g. docs/configuration.md (default: print it)")
    text = "a run's effective configuration as TOML: trustfg's defaults, then the file; every key."
    show = sub.add_parser("show", allow_abbrev=False, help=text, description=text[0].upper() + text[1:])
    show.add_argument("--scenario", required=True, metavar="FILE|NAME",
                      help="a scenario file, or a shipped config's name (intersection, lab/fleet)")
    args = parser.parse_args(argv)
    if args.action == "reference":
        from .reference import render

        page = render()
        if args.out is None:
            sys.stdout.write(page)
        else:
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(page, encoding="utf-8")
            print(f"wrote {args.out}")
        return 0
    from ..scenario_files import load_scenario  # the loader sits above the config it fills
    from .toml_text import effective_toml

    try:
        scenario = load_scenario(args.scenario)
    except ConfigError as exc:
        print(f"trustfg config: {exc}", file=sys.stderr)
        return 2
    sys.stdout.write(effective_toml(scenario, args.scenario))
    return 0


if __name__ == "__main__":
    sys.exit(main())
