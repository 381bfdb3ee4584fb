"""The reproductions of docs/platform.md still show what the notes say (so a note goes stale
loudly when Mitsuba changes), and our loader still undoes what they show."""
import subprocess
import sys
from pathlib import Path

REPRO = Path(__file__).resolve().parents[1] / "scripts" / "repro"


def test_plugin_constructor_error_reaches_load_dict_as_text_in_a_runtime_error(variant):
    """A Python BSDF raising ValueError in its constructor: ``mi.load_dict`` raises a
    RuntimeError with nothing chained, whose text is Mitsuba's location, the Python
    traceback (one line per frame) and the ValueError's line; ``_translate_load_error``
    (the loader of the CLI and ``mi_displace.render.scene.load``) makes it one line again."""
    import mitsuba as mi
    from mi_displace.render.scene import _translate_load_error

    run = subprocess.run([sys.executable, str(REPRO / "python_plugin_error.py"), variant],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    versions, kind, *message = run.stdout.splitlines()
    assert versions == f"mitsuba {mi.__version__}, drjit {__import__('drjit').__version__}, variant {variant}"
    assert kind == "RuntimeError, __cause__ None, __context__ None"
    assert message[0].startswith('[parser.cpp:') and message[0].endswith(
        'plugin of type "raising": Traceback (most recent call last):')
    assert [line.split(", in ")[-1] for line in message[1:-1]] == ["<module>", "<lambda>", "__init__"]
    assert message[-1] == "ValueError: raising: parameter 'roughness' must be > 0, got -1"
    user = _translate_load_error(Path("scene.xml"), RuntimeError("\n".join(message)))
    assert type(user) is ValueError and "\n" not in str(user) and "Traceback" not in str(user)
    assert str(user).startswith("scene 'scene.xml': At dictionary node \"root\": failed to instantiate")
    assert str(user).endswith("\"raising\": raising: parameter 'roughness' must be > 0, got -1")
