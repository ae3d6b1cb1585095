"""Package list for setuptools (everything else is in pyproject.toml).

The demo's inputs live at the repository root (``samples/``: photos, meshes, ``scenes.json``; ``calib/``: the
calibrations they name) and are shipped inside the wheel as ``arshadow/demo_data/samples`` and
``arshadow/demo_data/calib`` (found by :func:`arshadow.demo.data.data_root`), so that ``arshadow demo`` and
``arshadow bench`` work from an installed wheel. A root folder mapped into the package needs ``package_dir``,
which ``[tool.setuptools.packages.find]`` cannot be combined with; the files shipped are listed in
``[tool.setuptools.package-data]``.
"""

from setuptools import find_packages, setup

DEMO_DATA = {"arshadow.demo_data.samples": "samples", "arshadow.demo_data.calib": "calib"}

setup(packages=[*find_packages(include=["arshadow", "arshadow.*"]), *DEMO_DATA], package_dir=DEMO_DATA)
