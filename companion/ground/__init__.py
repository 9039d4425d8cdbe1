"""The ground link: operators command the vehicle and watch it over MQTT.

`protocol` (pure) defines the versioned JSON commands, acks, status and events and the topic
scheme `wireavoid/<vehicle_id>/cmd|ack|status|events`; `geofence` (pure) says whether a goal
and the leg to it stay inside the configured fence; `link.GroundLink` is the vehicle's aiomqtt
client; `station.GroundStation` is the operator's (`wireavoid gcs`); `params` holds
`GroundParams` and `GeofenceParams`.
"""
