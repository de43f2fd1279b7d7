"""The README's Python example runs as written."""

import re
from pathlib import Path

README = Path(__file__).resolve().parent.parent / "README.md"


def test_the_python_example_runs(tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks, "the README has no Python example"
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(blocks[0], "README.md", "exec"), namespace)
    assert (tmp_path / "results" / "toy.h5").is_file()
    assert namespace["result"].std("y").shape == (201,)


def test_the_example_config_is_the_quick_start_config():
    import yaml

    blocks = re.findall(r"```yaml\n(.*?)```", README.read_text(), flags=re.S)
    shown = yaml.safe_load(blocks[0])
    config = yaml.safe_load((README.parent / "configs" / "quarter_car.yaml").read_text())
    del config["sweep"]
    assert shown == config
