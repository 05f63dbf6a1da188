"""Cities, factories and the paper's defaults (docs/dataset.md)."""

from __future__ import annotations

from dataclasses import dataclass

from ..protocol import PAPER_SEED


@dataclass(frozen=True)
class City:
    """A market city: name and centre coordinates in decimal degrees (WGS84)."""

    name: str
    latitude: float
    longitude: float

    @property
    def node_prefix(self) -> str:
        return self.name[:3].upper()


@dataclass(frozen=True)
class Factory:
    factory_id: str
    city: str


#: The paper's five cities, in build order (docs/dataset.md#nodes).
PAPER_CITIES: tuple[City, ...] = (
    City("Beijing", 39.9042, 116.4074),
    City("Shanghai", 31.2304, 121.4737),
    City("Chengdu", 30.5728, 104.0668),
    City("Shenzhen", 22.5431, 114.0579),
    City("Hangzhou", 30.2741, 120.1551),
)

#: The paper's six buying factories, in trade-slot order (docs/dataset.md#p2p-trades).
PAPER_FACTORIES: tuple[Factory, ...] = (
    Factory("FAC-BJ-01", "Beijing"),
    Factory("FAC-SH-01", "Shanghai"),
    Factory("FAC-CD-01", "Chengdu"),
    Factory("FAC-SZ-01", "Shenzhen"),
    Factory("FAC-HZ-01", "Hangzhou"),
    Factory("FAC-SH-02", "Shanghai"),
)

DEFAULT_TIMEZONE = "Asia/Shanghai"
DEFAULT_SEED = PAPER_SEED
DEFAULT_START = "2026-04-01"
DEFAULT_END = "2026-05-01"
DEFAULT_NODES_PER_CITY = 10


def factories_for(cities: tuple[City, ...] | list[City]) -> tuple[Factory, ...]:
    """The paper's factories for the paper's cities; one factory per city otherwise."""
    if tuple(cities) == PAPER_CITIES:
        return PAPER_FACTORIES
    return tuple(Factory(f"FAC-{city.name[:2].upper()}-{i + 1:02d}", city.name) for i, city in enumerate(cities))


def parse_city(text: str) -> City:
    """Parse ``NAME:LAT:LON`` (e.g. ``Wuhan:30.5928:114.3055``)."""
    parts = text.split(":")
    if len(parts) != 3:
        raise ValueError(f"city '{text}' must be NAME:LAT:LON, e.g. Wuhan:30.5928:114.3055")
    name, lat, lon = parts[0].strip(), parts[1], parts[2]
    try:
        latitude, longitude = float(lat), float(lon)
    except ValueError:
        raise ValueError(f"city '{text}': latitude and longitude must be numbers") from None
    if not name:
        raise ValueError(f"city '{text}': the name is empty")
    if not (-90.0 <= latitude <= 90.0 and -180.0 <= longitude <= 180.0):
        raise ValueError(f"city '{text}': coordinates out of range")
    return City(name, latitude, longitude)


def check_unique_prefixes(cities: tuple[City, ...] | list[City]) -> None:
    seen: dict[str, str] = {}
    for city in cities:
        if city.node_prefix in seen:
            raise ValueError(
                f"cities '{seen[city.node_prefix]}' and '{city.name}' share the node-id prefix "
                f"'{city.node_prefix}'; rename one of them"
            )
        seen[city.node_prefix] = city.name


def synthetic_cities(count: int) -> tuple[City, ...]:
    """``count`` made-up cities for scale and sensitivity runs (synthetic weather only).

    City i is named by three letters (base 26 of i: "Baa", "Bab", …, so node-id prefixes are
    unique) and placed by a Kronecker sequence over latitudes 22–40° N and longitudes 100–122° E,
    the span of the paper's cities. Deterministic: city i does not depend on ``count``.
    """
    if not 1 <= count <= 25 * 26 * 26:
        raise ValueError(f"the number of synthetic cities must be in 1..{25 * 26 * 26}, got {count}")
    letters = "abcdefghijklmnopqrstuvwxyz"
    cities = []
    for i in range(count):
        name = letters[1 + i // 676].upper() + letters[(i // 26) % 26] + letters[i % 26]
        latitude = 22.0 + 18.0 * ((0.5 + i * 0.6180339887) % 1.0)
        longitude = 100.0 + 22.0 * ((0.5 + i * 0.7548776662) % 1.0)
        cities.append(City(name, round(latitude, 4), round(longitude, 4)))
    return tuple(cities)
