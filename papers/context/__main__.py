"""`python -m papers.context`: the context paper's experiments and REPORT.md."""

from ..runner import paper_main

if __name__ == "__main__":
    paper_main("context")
