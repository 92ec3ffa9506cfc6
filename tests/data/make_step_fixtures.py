"""Write the STEP fixtures of tests/test_step.py (run once; the .step files are committed).

gmsh (its OpenCASCADE kernel) is not a dependency of scanplan: install it anywhere, e.g.
`pip install --target /tmp/gmshpkg gmsh` (copy the wheel's data/lib/libgmsh.so.* into
/tmp/gmshpkg/lib if pip left it out), then `PYTHONPATH=/tmp/gmshpkg python make_step_fixtures.py`.
The inch and metre variants are the millimetre files with their length unit rewritten, so the
same numbers mean 25.4 or 1000 times more.
"""

from __future__ import annotations

from pathlib import Path

import gmsh

HERE = Path(__file__).parent


def _write(name: str, build) -> Path:
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add(name)
    build(gmsh.model.occ)
    gmsh.model.occ.synchronize()
    path = HERE / f"{name}.step"
    gmsh.write(str(path))
    gmsh.finalize()
    return path


def box(occ) -> None:  # 200 x 100 x 50 mm
    occ.addBox(0, 0, 0, 200, 100, 50)


def filleted_box(occ) -> None:  # 120 x 80 x 40 mm, every edge rounded r = 10 mm
    occ.addBox(0, 0, 0, 120, 80, 40, 1)
    occ.synchronize()
    edges = [tag for _, tag in gmsh.model.getEntities(1)]
    occ.fillet([1], edges, [10.0])


def plate_with_holes(occ) -> None:  # 300 x 200 x 10 mm, four through holes r = 15 mm
    occ.addBox(0, 0, 0, 300, 200, 10, 1)
    holes = [
        (2 + i, occ.addCylinder(x, y, -1, 0, 0, 12, 15, 2 + i))
        for i, (x, y) in enumerate([(50, 50), (250, 50), (50, 150), (250, 150)])
    ]
    occ.cut([(3, 1)], [(3, t) for _, t in holes])


def small_box(occ) -> None:  # 3 x 2 x 1 "units": rewritten to inches and metres below
    occ.addBox(0, 0, 0, 3, 2, 1)


def main() -> None:
    _write("box", box)
    _write("filleted_box", filleted_box)
    _write("plate_with_holes", plate_with_holes)
    small = _write("small_box", small_box)
    text = small.read_text()
    mm_unit = "( LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT(.MILLI.,.METRE.) )"
    assert mm_unit in text
    (HERE / "small_box_m.step").write_text(
        text.replace(mm_unit, "( LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT($,.METRE.) )")
    )
    # An inch is a conversion-based unit: 25.4 of the file's millimetre unit entity.
    inch = (
        "( CONVERSION_BASED_UNIT('INCH',#9001) LENGTH_UNIT() NAMED_UNIT(#9002) );\n"
        "#9001 = LENGTH_MEASURE_WITH_UNIT(LENGTH_MEASURE(25.4),#9003);\n"
        "#9002 = DIMENSIONAL_EXPONENTS(1.,0.,0.,0.,0.,0.,0.);\n"
        "#9003 = ( LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT(.MILLI.,.METRE.) )"
    )
    (HERE / "small_box_in.step").write_text(text.replace(mm_unit, inch, 1))
    small.unlink()


if __name__ == "__main__":
    main()
