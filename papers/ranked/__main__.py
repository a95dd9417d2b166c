"""`python -m papers.ranked`: the ranked-signal paper's figures and REPORT.md."""

from ..runner import paper_main

if __name__ == "__main__":
    paper_main("ranked")
