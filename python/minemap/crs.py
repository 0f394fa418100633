"""The grid's coordinate reference system as the files want it: OGC WKT (version 1, as LAS 1.4's WKT
record and E57's coordinateMetadata hold it), from the EPSG code of a control file (report.json
``control.epsg``).

Written here without a projection library, for the grids mines use most: the UTM zones of WGS 84
(EPSG 32601-32660 north, 32701-32760 south) and of ETRS89 (EPSG 25828-25838). Any other code gives
None, and the writers say that the CRS was left out of the file (report.json still names it).
"""
from __future__ import annotations

_DATUMS = {
    "WGS 84": ('DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563,AUTHORITY["EPSG","7030"]],'
               'AUTHORITY["EPSG","6326"]]', "4326"),
    "ETRS89": ('DATUM["European_Terrestrial_Reference_System_1989",SPHEROID["GRS 1980",6378137,298.257222101,'
               'AUTHORITY["EPSG","7019"]],AUTHORITY["EPSG","6258"]]', "4258"),
}


def _utm(epsg: int) -> tuple[str, int, bool] | None:
    """(datum, zone, north) of a UTM code, or None."""
    if 32601 <= epsg <= 32660:
        return "WGS 84", epsg - 32600, True
    if 32701 <= epsg <= 32760:
        return "WGS 84", epsg - 32700, False
    if 25828 <= epsg <= 25838:
        return "ETRS89", epsg - 25800, True
    return None


def wkt(epsg: int | None) -> str | None:
    """WKT 1 of the EPSG code, or None where it is not one of the UTM grids above (or None)."""
    if epsg is None:
        return None
    utm = _utm(int(epsg))
    if utm is None:
        return None
    datum, zone, north = utm
    datum_wkt, geographic = _DATUMS[datum]
    name = f"{datum} / UTM zone {zone}{'N' if north else 'S'}"
    return (f'PROJCS["{name}",GEOGCS["{datum}",{datum_wkt},PRIMEM["Greenwich",0,AUTHORITY["EPSG","8901"]],'
            f'UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],AUTHORITY["EPSG","{geographic}"]],'
            f'PROJECTION["Transverse_Mercator"],PARAMETER["latitude_of_origin",0],'
            f'PARAMETER["central_meridian",{6 * zone - 183}],PARAMETER["scale_factor",0.9996],'
            f'PARAMETER["false_easting",500000],PARAMETER["false_northing",{0 if north else 10000000}],'
            f'UNIT["metre",1,AUTHORITY["EPSG","9001"]],AXIS["Easting",EAST],AXIS["Northing",NORTH],'
            f'AUTHORITY["EPSG","{int(epsg)}"]]')


def left_out(epsg: int | None, path) -> list[str]:
    """The warning for a file that cannot carry the grid's CRS (empty when it can, or none is known)."""
    if epsg is None or wkt(epsg) is not None:
        return []
    return [f"{path}: EPSG:{int(epsg)} is not written into the file (only the WGS 84 and ETRS89 UTM zones are "
            f"known without a projection library); report.json names it"]
