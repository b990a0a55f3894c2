"""Generate ``loci-commonsense.owl``, the innate knowledge of the conceptual map (book Fig. 7.4).

A development-time script: the generated RDF/XML file is committed and is what the agent
loads; run this again after editing the tables below and commit both.

    python ontology/build_commonsense.py [OUT]      # default: ontology/loci-commonsense.owl

Every class gets an ``rdfs:label`` (the word people use, "living room") and optional
``skos:altLabel`` synonyms ("lounge"), which is how words map to classes. Room subtypes are
*defined* by the objects they hold (``LivingRoom ≡ Room ⊓ ∃hasObject.(Couch ⊔ Television)``),
so a reasoner can infer them from what the robot has seen.
"""

from __future__ import annotations

import sys
from pathlib import Path

import owlready2 as owl  # type: ignore[import-untyped]

IRI = "http://genius-loci.org/ontology/commonsense.owl"
VERSION = "1.0.0"
SKOS = "http://www.w3.org/2004/02/skos/core#"

# name: (parent, label, synonyms, comment)
AREAS: dict[str, tuple[str | None, str, tuple[str, ...], str]] = {
    "Area": (
        None,
        "area",
        ("place",),
        "A topological area of the map (Sect. 7.2.3): nodes between doorways.",
    ),
    "Room": ("Area", "room", (), "An area classified as a room from its laser scans."),
    "Corridor": ("Area", "corridor", ("passage",), "An area classified as a corridor."),
    "Hallway": ("Area", "hallway", ("lobby", "entrance hall"), "An area classified as a hallway."),
    "Doorway": ("Area", "doorway", ("door opening",), "A doorway between two areas."),
}

# room subtypes: name: (label, synonyms, defining object kinds (empty: asserted only), comment)
ROOM_TYPES: dict[str, tuple[str, tuple[str, ...], tuple[str, ...], str]] = {
    "LivingRoom": (
        "living room",
        ("lounge", "sitting room"),
        ("Couch", "Television"),
        "A room with a couch or a TV set.",
    ),
    "Kitchen": (
        "kitchen",
        ("kitchenette",),
        ("Fridge", "CoffeeMachine", "Stove", "Microwave"),
        "A room where food and coffee are made.",
    ),
    "Office": ("office", ("study", "workroom"), ("Desk", "Monitor"), "A room to work at a desk."),
    "Library": ("library", ("reading room",), ("Bookcase",), "A room with bookcases."),
    "Bedroom": ("bedroom", (), ("Bed",), "A room to sleep in."),
    "Bathroom": (
        "bathroom",
        ("washroom", "restroom"),
        ("Toilet", "Bathtub", "Shower"),
        "A room with a toilet, bath or shower.",
    ),
    "MeetingRoom": (
        "meeting room",
        ("conference room", "seminar room"),
        ("Projector", "ConferenceTable"),
        "A room for meetings.",
    ),
    "PrinterRoom": (
        "printer room",
        ("copy room",),
        ("Printer", "Photocopier"),
        "A room with printers or copiers.",
    ),
    "DiningRoom": ("dining room", (), (), "A room to eat in (named by people; no defining object)."),
    "RecreationRoom": (
        "recreation room",
        ("common room", "break room"),
        (),
        "A room to rest in (named by people).",
    ),
    "Laboratory": ("laboratory", ("lab",), (), "A room for experiments (named by people)."),
    "StorageRoom": (
        "storage room",
        ("storeroom", "closet"),
        (),
        "A room to keep things in (named by people).",
    ),
}

# object kinds: name: (parent, label, synonyms)
OBJECTS: dict[str, tuple[str, str, tuple[str, ...]]] = {
    "Object": ("", "object", ("thing",)),
    "Furniture": ("Object", "furniture", ()),
    "Appliance": ("Object", "appliance", ("device", "machine")),
    "Fixture": ("Object", "fixture", ()),
    "Couch": ("Furniture", "couch", ("sofa", "settee")),
    "Bookcase": ("Furniture", "bookcase", ("bookshelf", "shelf")),
    "Desk": ("Furniture", "desk", ()),
    "Table": ("Furniture", "table", ()),
    "ConferenceTable": ("Table", "conference table", ("meeting table",)),
    "Chair": ("Furniture", "chair", ()),
    "Bed": ("Furniture", "bed", ()),
    "Television": ("Appliance", "television", ("tv", "tv set", "television set", "telly")),
    "Monitor": ("Appliance", "monitor", ("screen", "computer screen", "display")),
    "Computer": ("Appliance", "computer", ("pc", "laptop")),
    "CoffeeMachine": ("Appliance", "coffee machine", ("coffee maker",)),
    "Fridge": ("Appliance", "fridge", ("refrigerator",)),
    "Stove": ("Appliance", "stove", ("cooker", "oven")),
    "Microwave": ("Appliance", "microwave", ("microwave oven",)),
    "Printer": ("Appliance", "printer", ()),
    "Photocopier": ("Appliance", "photocopier", ("copier", "copy machine")),
    "Projector": ("Appliance", "projector", ("beamer",)),
    "ChargingStation": ("Appliance", "charging station", ("charger", "docking station", "dock")),
    "Sink": ("Fixture", "sink", ("basin",)),
    "Toilet": ("Fixture", "toilet", ("loo",)),
    "Bathtub": ("Fixture", "bathtub", ("bath", "tub")),
    "Shower": ("Fixture", "shower", ()),
    "Whiteboard": ("Fixture", "whiteboard", ("blackboard",)),
    "Bucket": ("Object", "bucket", ("pail",)),
    "Books": ("Object", "books", ("book",)),
    "Plant": ("Object", "plant", ("pot plant",)),
}

# bookkeeping annotations the conceptual map writes on its individuals (ignored by reasoners)
ANNOTATIONS: dict[str, str] = {
    "seenFrom": "The navigation node an object was last seen from (integer).",
    "source": "Who put a fact in the map: 'camera' or the name of a person.",
    "statement": "A tutor's statement about an area, as JSON: kind (type|name), word, class, speaker.",
    "mapVersion": "The change counter of the conceptual map (integer).",
}


def build(out: Path) -> Path:
    """Write the ontology to ``out`` (RDF/XML) and return the path."""
    world = owl.World()
    onto = world.get_ontology(IRI)
    skos = onto.get_namespace(SKOS)
    onto.metadata.versionInfo.append(VERSION)
    onto.metadata.comment.append(
        owl.locstr(
            "Commonsense knowledge of office and home environments for the conceptual map of "
            "genius-loci (after Mozos 2010, Sect. 7.2.4, Fig. 7.4): areas, objects, and room "
            "types defined by the objects they hold.",
            "en",
        )
    )
    classes: dict[str, owl.ThingClass] = {}
    with onto:

        class altLabel(owl.AnnotationProperty):  # noqa: N801  (SKOS's own name)
            namespace = skos

        def make(name: str, parent: str | None, label: str, synonyms: tuple[str, ...]) -> owl.ThingClass:
            base = classes[parent] if parent else owl.Thing
            cls = owl.types.new_class(name, (base,))
            cls.label = [owl.locstr(label, "en")]
            cls.altLabel = [owl.locstr(s, "en") for s in synonyms]
            classes[name] = cls
            return cls

        for name, (parent, label, syn, comment) in AREAS.items():
            make(name, parent, label, syn).comment = [owl.locstr(comment, "en")]
        for name, (parent, label, syn) in OBJECTS.items():
            make(name, parent or None, label, syn)
        owl.AllDisjoint([classes["Area"], classes["Object"]])
        owl.AllDisjoint([classes[n] for n in ("Room", "Corridor", "Hallway", "Doorway")])
        # siblings under one parent are disjoint: an object instance has one kind
        by_parent: dict[str, list[str]] = {}
        for name, (parent, _, _) in OBJECTS.items():
            if parent:
                by_parent.setdefault(parent, []).append(name)
        for siblings in by_parent.values():
            if len(siblings) > 1:
                owl.AllDisjoint([classes[n] for n in siblings])

        hasObject = owl.types.new_class("hasObject", (owl.ObjectProperty,))
        hasObject.domain = [classes["Area"]]
        hasObject.range = [classes["Object"]]
        hasObject.label = [owl.locstr("has object", "en")]
        hasObject.comment = [owl.locstr("The has-a relation of Fig. 7.2: an object found in an area.", "en")]
        isIn = owl.types.new_class("isIn", (owl.ObjectProperty,))
        isIn.inverse_property = hasObject
        isIn.label = [owl.locstr("is in", "en")]
        isIn.comment = [owl.locstr("The inverse of hasObject: the area an object is in.", "en")]

        for name, (label, syn, defining, comment) in ROOM_TYPES.items():
            cls = make(name, "Room", label, syn)
            cls.comment = [owl.locstr(comment, "en")]
            if defining:
                kinds = [classes[k] for k in defining]
                filler = kinds[0] if len(kinds) == 1 else owl.Or(kinds)
                cls.equivalent_to = [classes["Room"] & hasObject.some(filler)]

        for name, comment in ANNOTATIONS.items():
            prop = owl.types.new_class(name, (owl.AnnotationProperty,))
            prop.comment = [owl.locstr(comment, "en")]
    out.parent.mkdir(parents=True, exist_ok=True)
    onto.save(file=str(out), format="rdfxml")
    world.close()
    return out


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name("loci-commonsense.owl")
    print(build(target))
