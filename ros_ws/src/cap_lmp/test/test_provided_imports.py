"""Imports of names the sandbox already provides are dropped before the check; every other import is refused."""
from __future__ import annotations

import pytest

from cap_lmp.engine import Engine, LMPConfig
from cap_lmp.llm import OpenAICompatibleClient
from cap_lmp.provided_imports import drop_provided_imports
from cap_lmp.testing.openai_server import ScriptedOpenAIServer

SCOPE = {'np', 'Point', 'Polygon', 'rotate', 'unary_union', 'say'}


@pytest.mark.parametrize('statement', ['import numpy as np', 'from shapely.geometry import Point, Polygon',
                                       'from shapely import Point', 'from shapely.affinity import rotate',
                                       'from shapely.ops import unary_union'])
def test_an_import_of_provided_names_becomes_a_commented_pass(statement):
    dropped = drop_provided_imports(f'{statement}\nsay(1)\n', SCOPE)
    assert dropped == f'pass  # {statement} (already provided)\nsay(1)\n'


@pytest.mark.parametrize('statement', ['import numpy', 'import numpy as numbers', 'import os', 'import math',
                                       'from numpy import array', 'from shapely.geometry import Point as P',
                                       'from shapely.wkt import loads', 'from . import np',
                                       'x = 1; import numpy as np'])
def test_other_imports_stay_for_the_check_to_refuse(statement):
    assert drop_provided_imports(f'{statement}\n', SCOPE) == f'{statement}\n'


def test_an_import_inside_a_function_keeps_the_block_valid_and_the_lines():
    source = 'def f():\n    import numpy as np\n    return np.pi\n'
    assert drop_provided_imports(source, SCOPE) == \
        'def f():\n    pass  # import numpy as np (already provided)\n    return np.pi\n'


def test_the_engine_runs_code_that_imports_what_it_has_and_refuses_the_rest():
    answers = {'# use numpy': 'import numpy as np\nfrom shapely.geometry import Point\nsay(round(np.pi, 2))',
               '# use os': 'import os\nsay(os.getcwd())'}
    said = []
    with ScriptedOpenAIServer(answers, fence_chat=False) as server:
        client = OpenAICompatibleClient(server.base_url, server.model, api='completions', max_retries=0)
        engine = Engine([LMPConfig('main', '', stop=('\n#',))], client, {'say': said.append}, fgen_lmp=None)
        done = engine.run('use numpy')
        refused = engine.run('use os')
    assert done.success, done.message
    assert said == [3.14] and 'import numpy as np (already provided)' in done.code
    assert not refused.success and 'imports are not allowed' in refused.message
