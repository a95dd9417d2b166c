"""`python -m papers [--quick] [--out figures]`: every paper's experiments and reports."""

from .runner import main

if __name__ == "__main__":
    main()
