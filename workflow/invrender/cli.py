"""The `invrender` command: one subcommand per stage. It only parses arguments."""

import argparse
import sys


def main(argv=None):
    parser = argparse.ArgumentParser(prog="invrender", description=__doc__)
    parser.add_subparsers(dest="stage", required=True)
    args = parser.parse_args(argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
