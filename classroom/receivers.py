"""What the classroom hears from the rest of robotide: an attempt's runs starting and ending
(programs.models.run_started / run_ended), in whichever process marks them (the web tier's,
or a robot agent's: fleet mode's ``robotide agent``); classroom.checking keeps nothing in
memory between them."""

from django.dispatch import receiver

from programs.models import run_ended, run_started


@receiver(run_ended, dispatch_uid="classroom.run_ended")
def _run_ended(sender, run_id: int, **kwargs) -> None:
    from classroom import checking

    checking.run_ended(run_id)


@receiver(run_started, dispatch_uid="classroom.run_started")
def _run_started(sender, run_id: int, **kwargs) -> None:
    from classroom import checking

    checking.run_started(run_id)
