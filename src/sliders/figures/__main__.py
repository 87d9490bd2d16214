"""``python -m sliders.figures``: the paper's figures, the gallery, the animation."""

import sys

from .paper import main

if __name__ == "__main__":
    sys.exit(main())
