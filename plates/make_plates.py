"""Regenerate the sample plates in this folder from the built-in template (deterministic).

    python plates/make_plates.py
"""
from pathlib import Path

import invface
from invface.fit.samples import write_sample_plates

if __name__ == "__main__":
    model = invface.template.build()
    for p in write_sample_plates(model, Path(__file__).parent, progress=print):
        print("wrote", p)
