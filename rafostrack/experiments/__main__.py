"""`python -m rafostrack.experiments [--quick] [--out figures]`: every paper figure and REPORT.md."""

from rafostrack.experiments.report import main

if __name__ == "__main__":
    main()
