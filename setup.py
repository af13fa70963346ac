"""Package data that lives outside the packages: the shipped models.

Everything else is in pyproject.toml. ``models/`` stays at the repository root
(where ``make models`` writes and people look); a wheel installs it as the
package ``monitor.shipped``, which ``monitor.resources`` reads through
``importlib.resources`` when there is no checkout around the code.
"""

from setuptools import find_packages, setup

setup(
    packages=find_packages(include=["monitor*", "offline*", "fleet*"]) + ["monitor.shipped", "monitor.shipped.propellers"],
    package_dir={"monitor.shipped": "models"},
)
