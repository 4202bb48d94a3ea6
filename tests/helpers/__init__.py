"""What several test modules share, so that a test module imports only the package and these:
file paths (:mod:`.paths`), a ``modular-robots run`` in a child process (:mod:`.runs`), robot
models built by hand (:mod:`.models`), MuJoCo as an independent engine (:mod:`.mujoco_engine`),
and a paper-5kg shooting problem with its solve history (:mod:`.problems`). Fixtures stay in
``tests/conftest.py``."""
