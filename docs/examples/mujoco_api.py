"""The study of mujoco_pendulum_bind.yaml built in Python (docs/models.md).

    python docs/examples/mujoco_api.py

The scene is given as a factory (picklable, so worker processes can build it); its keys are
the YAML's, as plain dicts.
"""

from pathlib import Path

import numpy as np

import pcmb

XML = Path(__file__).resolve().parents[2] / "models" / "mujoco" / "pendulum.xml"


def main(jobs=None):  # None: as many workers as cores, if workers pay
    scene = pcmb.MujocoModelFactory(
        xml=XML,
        params={"L": 1.0, "theta0": np.pi / 4, "gz": -9.81},
        bind={"theta0": [{"qpos0": "hinge"}], "gz": [{"field": "opt.gravity", "index": 2}]},
        init={},
        outputs={
            "theta": {"qpos": "hinge"},
            "omega": {"qvel": "hinge"},
            "bob_x": {"xpos": "bob", "axis": 0},
        },
    )
    study = pcmb.Study(
        scene,
        {"theta0": pcmb.Uniform(0.6, 1.0), "gz": pcmb.Uniform(-10.3, -9.3)},
        np.linspace(0.0, 3.0, 301),
        order=4,
        nominal={"theta0": np.pi / 4, "gz": -9.81},  # a factory takes no params: say it here
        jobs=jobs,
    )
    result = study.run()
    print(f"theta(3) mean {result.mean('theta')[-1]:+.10f}, std {result.std('theta')[-1]:.10f}")
    return result


if __name__ == "__main__":
    main()
