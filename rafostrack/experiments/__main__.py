"""`python -m rafostrack.experiments [--quick] [--out figures]`: every paper's experiments and reports."""

from rafostrack.experiments.runner import main

if __name__ == "__main__":
    main()
