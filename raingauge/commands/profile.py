"""Show and validate a camera profile.

Prints the validated profile (all keys, defaults filled in) as TOML, or the
error that names the key to fix.  ``raingauge profile --list`` lists the
profiles shipped with raingauge.
"""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("camera", nargs="?", default=None,
                        help="profile TOML file or shipped name (default: gauge-default)")
    parser.add_argument("--list", action="store_true", help="list the shipped profiles")


def run(args: argparse.Namespace) -> int:
    from raingauge.profile import load_profile, profile_to_toml, shipped_profiles

    if args.list:
        for name in shipped_profiles():
            print(name)
        return 0
    profile = load_profile(args.camera)
    print(profile_to_toml(profile), end="")
    return 0
