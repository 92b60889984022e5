/* amsfe_lifecycle.c: see amsfe_lifecycle.h. */
#include "amsfe_lifecycle.h"

#include <rcl_lifecycle/default_state_machine.h>
#include <rcutils/error_handling.h>
#include <lifecycle_msgs/msg/state.h>
#include <lifecycle_msgs/msg/transition.h>
#include <lifecycle_msgs/msg/transition_description.h>
#include <lifecycle_msgs/msg/transition_event.h>
#include <lifecycle_msgs/srv/change_state.h>
#include <lifecycle_msgs/srv/get_available_states.h>
#include <lifecycle_msgs/srv/get_available_transitions.h>
#include <lifecycle_msgs/srv/get_state.h>
#include <rosidl_runtime_c/string_functions.h>

static void serve_introspection(node_lifecycle *lc);

rcl_ret_t lifecycle_init(node_lifecycle *lc, rcl_node_t *node) {
  lc->sm = rcl_lifecycle_get_zero_initialized_state_machine();
  rcl_lifecycle_state_machine_options_t opts = rcl_lifecycle_get_default_state_machine_options();
  opts.enable_com_interface = true;
  opts.initialize_default_states = true;
  rcl_ret_t ret = rcl_lifecycle_state_machine_init(
      &lc->sm, node, ROSIDL_GET_MSG_TYPE_SUPPORT(lifecycle_msgs, msg, TransitionEvent),
      ROSIDL_GET_SRV_TYPE_SUPPORT(lifecycle_msgs, srv, ChangeState),
      ROSIDL_GET_SRV_TYPE_SUPPORT(lifecycle_msgs, srv, GetState),
      ROSIDL_GET_SRV_TYPE_SUPPORT(lifecycle_msgs, srv, GetAvailableStates),
      ROSIDL_GET_SRV_TYPE_SUPPORT(lifecycle_msgs, srv, GetAvailableTransitions),
      ROSIDL_GET_SRV_TYPE_SUPPORT(lifecycle_msgs, srv, GetAvailableTransitions), &opts);
  lc->enabled = ret == RCL_RET_OK;
  return ret;
}

rcl_ret_t lifecycle_wait_add(node_lifecycle *lc, rcl_wait_set_t *ws) {
  rcl_lifecycle_com_interface_t *c = &lc->sm.com_interface;
  rcl_service_t *all[LIFECYCLE_SERVICES] = {
      &c->srv_change_state, &c->srv_get_state, &c->srv_get_available_states,
      &c->srv_get_available_transitions, &c->srv_get_transition_graph};
  rcl_ret_t ret = RCL_RET_OK;
  for (int i = 0; i < LIFECYCLE_SERVICES && ret == RCL_RET_OK; ++i)
    ret = rcl_wait_set_add_service(ws, all[i], NULL);
  return ret;
}

const char *lifecycle_state(const node_lifecycle *lc) {
  return lc->sm.current_state ? lc->sm.current_state->label : "unknown";
}

/* One transition by id through its intermediate state ("configuring", ...) to its goal:
 * 1 done (the node's reaction run), 0 not a transition of the current state. */
static int transition(node_lifecycle *lc, uint8_t id, void (*on)(void *, int), void *ctx) {
  if (rcl_lifecycle_trigger_transition_by_id(&lc->sm, id, true) != RCL_RET_OK) {
    rcutils_reset_error();
    return 0;
  }
  int event = LC_NONE;
  switch (id) {
    case lifecycle_msgs__msg__Transition__TRANSITION_ACTIVATE: event = LC_ACTIVATE; break;
    case lifecycle_msgs__msg__Transition__TRANSITION_DEACTIVATE: event = LC_DEACTIVATE; break;
    case lifecycle_msgs__msg__Transition__TRANSITION_UNCONFIGURED_SHUTDOWN:
    case lifecycle_msgs__msg__Transition__TRANSITION_INACTIVE_SHUTDOWN:
    case lifecycle_msgs__msg__Transition__TRANSITION_ACTIVE_SHUTDOWN: event = LC_SHUTDOWN; break;
    default: break;
  }
  if (event != LC_NONE && on) on(ctx, event);
  if (rcl_lifecycle_trigger_transition_by_label(&lc->sm, rcl_lifecycle_transition_success_label,
                                                true) != RCL_RET_OK) {
    rcutils_reset_error();
    return 0;
  }
  return 1;
}

void lifecycle_serve(node_lifecycle *lc, void (*on)(void *ctx, int event), void *ctx) {
  if (!lc->enabled) return;
  rcl_lifecycle_com_interface_t *c = &lc->sm.com_interface;
  rmw_request_id_t header;
  lifecycle_msgs__srv__ChangeState_Request req;
  lifecycle_msgs__srv__ChangeState_Response res;
  lifecycle_msgs__srv__ChangeState_Request__init(&req);
  lifecycle_msgs__srv__ChangeState_Response__init(&res);
  while (rcl_take_request(&c->srv_change_state, &header, &req) == RCL_RET_OK) {
    uint8_t id = req.transition.id;
    if (id == 0 && req.transition.label.data) { /* by label: its id from the current state */
      const rcl_lifecycle_transition_t *t =
          rcl_lifecycle_get_transition_by_label(lc->sm.current_state, req.transition.label.data);
      id = t ? (uint8_t)t->id : 0;
    }
    res.success = id != 0 && transition(lc, id, on, ctx);
    if (rcl_send_response(&c->srv_change_state, &header, &res) != RCL_RET_OK) rcutils_reset_error();
  }
  lifecycle_msgs__srv__ChangeState_Request__fini(&req);
  lifecycle_msgs__srv__ChangeState_Response__fini(&res);
  lifecycle_msgs__srv__GetState_Request greq;
  lifecycle_msgs__srv__GetState_Response gres;
  lifecycle_msgs__srv__GetState_Request__init(&greq);
  lifecycle_msgs__srv__GetState_Response__init(&gres);
  while (rcl_take_request(&c->srv_get_state, &header, &greq) == RCL_RET_OK) {
    gres.current_state.id = (uint8_t)lc->sm.current_state->id;
    rosidl_runtime_c__String__assign(&gres.current_state.label, lc->sm.current_state->label);
    if (rcl_send_response(&c->srv_get_state, &header, &gres) != RCL_RET_OK) rcutils_reset_error();
  }
  lifecycle_msgs__srv__GetState_Request__fini(&greq);
  lifecycle_msgs__srv__GetState_Response__fini(&gres);
  serve_introspection(lc);
}

/* A lifecycle_msgs/State from one of the machine's states. */
static void state_msg(lifecycle_msgs__msg__State *m, const rcl_lifecycle_state_t *st) {
  m->id = (uint8_t)st->id;
  rosidl_runtime_c__String__assign(&m->label, st->label);
}

/* `count` transitions of `list` as TransitionDescriptions (id, label, start, goal). */
static void describe_transitions(lifecycle_msgs__msg__TransitionDescription__Sequence *out,
                                 const rcl_lifecycle_transition_t *list,
                                 unsigned int count) {
  if (!lifecycle_msgs__msg__TransitionDescription__Sequence__init(out, count)) return;
  for (unsigned int i = 0; i < count; ++i) {
    const rcl_lifecycle_transition_t *t = &list[i];
    lifecycle_msgs__msg__TransitionDescription *d = &out->data[i];
    d->transition.id = (uint8_t)t->id;
    rosidl_runtime_c__String__assign(&d->transition.label, t->label);
    if (t->start) state_msg(&d->start_state, t->start);
    if (t->goal) state_msg(&d->goal_state, t->goal);
  }
}

/* The introspection services `ros2 lifecycle list` asks, answered as rclpy's lifecycle node
 * answers them: every state of the machine (primary and transition states), the transitions
 * of the current state, and the whole transition graph. */
static void serve_introspection(node_lifecycle *lc) {
  rcl_lifecycle_com_interface_t *c = &lc->sm.com_interface;
  const rcl_lifecycle_transition_map_t *map = &lc->sm.transition_map;
  rmw_request_id_t header;
  lifecycle_msgs__srv__GetAvailableStates_Request sreq;
  lifecycle_msgs__srv__GetAvailableStates_Request__init(&sreq);
  while (rcl_take_request(&c->srv_get_available_states, &header, &sreq) == RCL_RET_OK) {
    lifecycle_msgs__srv__GetAvailableStates_Response res;
    lifecycle_msgs__srv__GetAvailableStates_Response__init(&res);
    if (lifecycle_msgs__msg__State__Sequence__init(&res.available_states, map->states_size))
      for (unsigned int i = 0; i < map->states_size; ++i)
        state_msg(&res.available_states.data[i], &map->states[i]);
    if (rcl_send_response(&c->srv_get_available_states, &header, &res) != RCL_RET_OK)
      rcutils_reset_error();
    lifecycle_msgs__srv__GetAvailableStates_Response__fini(&res);
  }
  lifecycle_msgs__srv__GetAvailableStates_Request__fini(&sreq);
  rcl_service_t *srv[2] = {&c->srv_get_available_transitions, &c->srv_get_transition_graph};
  for (int which = 0; which < 2; ++which) {
    lifecycle_msgs__srv__GetAvailableTransitions_Request treq;
    lifecycle_msgs__srv__GetAvailableTransitions_Request__init(&treq);
    while (rcl_take_request(srv[which], &header, &treq) == RCL_RET_OK) {
      lifecycle_msgs__srv__GetAvailableTransitions_Response res;
      lifecycle_msgs__srv__GetAvailableTransitions_Response__init(&res);
      const rcl_lifecycle_state_t *now = lc->sm.current_state;
      if (which == 0)
        describe_transitions(&res.available_transitions, now->valid_transitions,
                             now->valid_transition_size);
      else
        describe_transitions(&res.available_transitions, map->transitions,
                             map->transitions_size);
      if (rcl_send_response(srv[which], &header, &res) != RCL_RET_OK) rcutils_reset_error();
      lifecycle_msgs__srv__GetAvailableTransitions_Response__fini(&res);
    }
    lifecycle_msgs__srv__GetAvailableTransitions_Request__fini(&treq);
  }
}

void lifecycle_fini(node_lifecycle *lc, rcl_node_t *node) {
  if (lc->enabled && rcl_lifecycle_state_machine_fini(&lc->sm, node) != RCL_RET_OK)
    rcutils_reset_error();
}
