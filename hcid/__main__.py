"""``python -m hcid``: the same as the ``hcid`` command."""

from hcid.cli import main

if __name__ == "__main__":
    main()
