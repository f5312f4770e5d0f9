from django.db import migrations, models


class Migration(migrations.Migration):
    dependencies = [
        ("programs", "0009_run_sealed"),
    ]

    operations = [
        migrations.AddField(
            model_name="run",
            name="debug",
            field=models.JSONField(
                blank=True, editable=False, null=True, verbose_name="debugger"
            ),
        ),
    ]
