"""`python -m papers.legs`: the random-walk leg paper's figures and REPORT.md."""

from ..runner import paper_main

if __name__ == "__main__":
    paper_main("legs")
