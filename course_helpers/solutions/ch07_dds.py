"""Reference solution of chapter 07's exercise (two teams on one machine)."""


def plan(kernel_domain: int, spare_domain: int) -> dict:
    """The team talks in the spare domain; the monitor stays with you; the loner switches discovery off."""
    team = {"ROS_DOMAIN_ID": str(spare_domain)}
    return {
        "talker": dict(team),
        "listener": dict(team),
        "monitor": {},  # inherits the kernel's domain and localhost discovery
        "loner": {"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"},
    }
