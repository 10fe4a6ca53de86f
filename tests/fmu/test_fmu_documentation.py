"""Every regulator FMU's documentation page renders docs/method.md, the one description of
the method, so the page and the document cannot drift; the renderer keeps what it is given."""
import zipfile

from fmu_src.packing import method_page

PAGE = "documentation/index.html"


def _page(fmu) -> str:
    with zipfile.ZipFile(fmu) as archive:
        return archive.read(PAGE).decode("utf-8")


def test_every_regulator_page_holds_docs_method_md(built_fmu, native_fmus):
    method = method_page.method_html()
    for fmu in (built_fmu, *native_fmus.values()):
        assert method in _page(fmu), f"{fmu.name}: {PAGE} does not render docs/method.md"


def test_method_md_renders_headings_lists_code_and_escapes():
    html = method_page.render("# T\n\nA `x<1` and b\ncontinued.\n\n- one\n  more\n- two\n\n```\nW <- W\n```\n## S\n")
    assert html == ("<h2>T</h2>\n<p>A <code>x&lt;1</code> and b continued.</p>\n"
                    "<ul>\n<li>one more</li>\n<li>two</li>\n</ul>\n<pre>W &lt;- W</pre>\n<h3>S</h3>\n")


def test_every_regulator_page_lists_the_tiers_the_profiles_and_each_parameters_tier(built_fmu, native_fmus):
    from fmu_src.core.avr_profiles import PROFILES
    from fmu_src.core.avr_specs import PARAM_SPECS
    from fmu_src.packing.parameters import parameters_html

    section = parameters_html()
    assert all(f"<code>profiles/{name}.ssv</code>" in section for name in PROFILES)
    assert "learn_ramp_max_mps2 &gt; 0 requires learn_settled_steps &gt; 0" in section
    for fmu in (built_fmu, *native_fmus.values()):
        page = _page(fmu)
        assert section in page, fmu.name
        for spec in PARAM_SPECS:  # the variables table's row: name, causality, tier, ...
            assert f"<td>{spec.name}</td><td>parameter</td><td>{spec.tier}</td>" in page, (fmu.name, spec.name)
