"""The config's ``analysis:`` section: accepted forms and located errors."""

import pytest

from pcmb.config.schema import load_config
from pcmb.errors import ConfigError
from pcmb.study import Study

# The fixture's grid: 0 .. 2 in 5 points, step 0.5, Nyquist 1 Hz; outputs y and z.


@pytest.fixture
def with_analysis(linear_study):
    """Write the linear study with an ``analysis:`` section; returns the config path."""

    def write(analysis):
        path = linear_study()
        path.write_text(path.read_text() + f"analysis: {analysis}\n")
        return path

    return write


def test_a_full_analysis_section(with_analysis):
    config = load_config(
        with_analysis(
            "{psd: [y], window: boxcar, pdf_times: [1.0, 2.0], pdf_freqs: [0.5, 1.0], "
            "quantiles: [0.1, 0.5, 0.9], samples: 5000, seed: 3, units: {y: m}, time_unit: s}",
        )
    )
    settings = config.analysis_settings
    assert settings.psd == ("y",) and settings.window == "boxcar"
    assert settings.pdf_times == (1.0, 2.0) and settings.pdf_freqs == (0.5, 1.0)
    assert settings.quantiles == (0.1, 0.5, 0.9) and settings.samples == 5000
    assert settings.units == {"y": "m"} and settings.time_unit == "s"


def test_the_study_takes_the_analysis_and_the_nominal_values(with_analysis):
    config = load_config(with_analysis("{pdf_times: [1.0]}"))
    study = Study.from_config(config)
    assert study.analysis == config.analysis_settings
    # model.params gives a = 1.0 and b = 0.0 (the inputs' means would be 2.0 and 0.0).
    assert study.nominal_params() == {"a": 1.0, "b": 0.0}


def test_defaults_and_absence(linear_study, with_analysis):
    assert load_config(linear_study()).analysis_settings is None
    settings = load_config(with_analysis("{}")).analysis_settings
    assert settings.psd is None and settings.pdf_times is None and settings.window == "hann"
    assert settings.quantiles == (0.05, 0.95)


@pytest.mark.parametrize(
    ("analysis", "expected"),
    [
        ("{psd: [w]}", r"analysis.psd\[0\]: 'w' is not an output \(y, z\)"),
        ("{pdf_times: [1.0, 2.5]}", r"analysis.pdf_times\[1\]: 2.5 is outside \[0.0, 2.0\]"),
        ("{pdf_freqs: [1.5]}", r"analysis.pdf_freqs\[0\]: 1.5 Hz is above the Nyquist"),
        ("{pdf_freqs: [-1.0]}", r"analysis.pdf_freqs\[0\]: expected a value >= 0"),
        ("{window: hammock}", r"analysis.window: expected one of boxcar, hann, .* found 'hammock'"),
        ("{quantiles: [0.0, 0.5]}", r"analysis.quantiles\[0\]: expected a value > 0"),
        ("{quantiles: [0.5, 0.5]}", r"analysis.quantiles: listed twice: 0.5"),
        ("{samples: 10}", r"analysis.samples: expected a value >= 100"),
        ("{units: {w: m}}", r"analysis.units.w: 'w' is not an output"),
        ("{psd: x}", r"analysis.psd: expected a list"),
        ("{pdf_time: [1.0]}", r"analysis.pdf_time: unknown key.*did you mean 'pdf_times'"),
    ],
)
def test_mistakes_name_their_key(with_analysis, analysis, expected):
    with pytest.raises(ConfigError, match=expected) as error:
        load_config(with_analysis(analysis))
    assert error.value.problems[0].line is not None  # located in the file
