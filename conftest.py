"""Import the Python package colorglove_ros before pytest imports any test module.

The tests live in colorglove_ros/test/, so pytest's importlib mode names them
colorglove_ros.test.<...> from this root and, finding no module colorglove_ros yet, would make
the package folder colorglove_ros/ (package.xml, setup.py, ..., no __init__.py) that module,
hiding the Python package colorglove_ros/colorglove_ros/ (first on sys.path: pytest.ini's
pythonpath)."""
import colorglove_ros  # noqa: F401
