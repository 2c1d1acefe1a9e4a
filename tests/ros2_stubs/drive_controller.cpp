// Test driver (tests/test_ros2_package.py): plays the controller manager's part for the
// package of `rrr-pin export --ros2`, against the stubs of this folder. Commands on stdin, one
// per line; answers on stdout (numbers with %.17g):
//   param NAME d VALUE | param NAME s TEXT | param NAME da K V1..VK | param NAME sa K S1..SK
//   init [RATE]               -> "init SUCCESS|ERROR"  (the plugin made by its exported name;
//                                the controller manager's update rate, default 1000 Hz)
//   configure                 -> "configure SUCCESS|ERROR"
//   activate Q1..Qn QD1..QDn  -> "activate SUCCESS|ERROR"
//   ref NP P.. NV V.. NA A..  -> (the subscription's callback, as the executor would call it)
//   update PERIOD Q.. QD..    -> "update OK|ERROR TAU1..TAUn fault CODE PERIOD_USED CLIPPED"
//   reason                    -> "reason TEXT"
//   deactivate                -> "deactivate SUCCESS|ERROR TAU1..TAUn"
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <new>
#include <utility>
#include <vector>

#include "pluginlib/class_list_macros.hpp"
// The package under test: -DRRR_PIN_PACKAGE=<name> (its namespace and include folder).
#ifndef RRR_PIN_PACKAGE
#define RRR_PIN_PACKAGE rrr_pin_controller
#endif
#define RRR_PIN_STR2(x) #x
#define RRR_PIN_STR(x) RRR_PIN_STR2(x)
#include RRR_PIN_STR(RRR_PIN_PACKAGE/exported_law_controller.hpp)

// Every C++ allocation of the process, counted (the global operator new replaced): update()
// must make none (issue 47). malloc called directly from C is not counted.
#if defined(__GNUC__) && !defined(__clang__)
// GCC sees the replaced operator new inlined next to std::free and warns; they do match here.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
static std::size_t g_allocations = 0;
void * operator new(std::size_t n)
{
  ++g_allocations;
  if (void * p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void * p) noexcept { std::free(p); }
void operator delete(void * p, std::size_t) noexcept { std::free(p); }

namespace
{
// A number token, "nan" and "inf" included (operator>> would refuse them).
double num(std::istream & in)
{
  std::string t;
  in >> t;
  return std::strtod(t.c_str(), nullptr);
}

const char * name_of(controller_interface::CallbackReturn r)
{
  return r == controller_interface::CallbackReturn::SUCCESS ? "SUCCESS" : "ERROR";
}
}  // namespace

int main()
{
  using Ctrl = RRR_PIN_PACKAGE::ExportedLawController;
  auto & registry = rrr_pin_stub::registry<controller_interface::ControllerInterface>();
  auto made = registry.at(RRR_PIN_STR(RRR_PIN_PACKAGE) "::ExportedLawController")();
  auto c = std::dynamic_pointer_cast<Ctrl>(made);
  std::vector<std::pair<std::string, rclcpp::ParameterValue>> overrides;
  double hw_state[2 * CTRL_NQ] = {0.0}, hw_command[CTRL_NQ] = {0.0};
  rclcpp::Subscription<trajectory_msgs::msg::JointTrajectoryPoint> * sub = nullptr;
  const rclcpp_lifecycle::State state;
  std::string line;
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  while (std::getline(std::cin, line)) {
    std::istringstream in(line);
    std::string cmd;
    in >> cmd;
    if (cmd == "param") {
      std::string name, kind;
      in >> name >> kind;
      if (kind == "d") {
        overrides.emplace_back(name, rclcpp::ParameterValue(num(in)));
      } else if (kind == "s") {
        std::string v;
        in >> v;
        overrides.emplace_back(name, rclcpp::ParameterValue(v));
      } else if (kind == "da") {
        std::size_t k;
        in >> k;
        std::vector<double> v(k);
        for (auto & x : v) x = num(in);
        overrides.emplace_back(name, rclcpp::ParameterValue(v));
      } else {
        std::size_t k;
        in >> k;
        std::vector<std::string> v(k);
        for (auto & x : v) in >> x;
        overrides.emplace_back(name, rclcpp::ParameterValue(v));
      }
    } else if (cmd == "init") {
      std::string token;
      const unsigned int rate = (in >> token) ? static_cast<unsigned int>(std::stoul(token)) : 1000u;
      std::printf("init %s\n", name_of(c->init(RRR_PIN_STR(RRR_PIN_PACKAGE), overrides, rate)));
    } else if (cmd == "configure") {
      const auto r = c->on_configure(state);
      if (r == controller_interface::CallbackReturn::SUCCESS) {
        auto node = c->get_node();
        sub = static_cast<rclcpp::Subscription<trajectory_msgs::msg::JointTrajectoryPoint> *>(
          node->subscriptions_.back().get());
      }
      std::printf("configure %s\n", name_of(r));
    } else if (cmd == "activate") {
      for (double & v : hw_state) v = num(in);
      std::vector<hardware_interface::LoanedCommandInterface> command;
      std::vector<hardware_interface::LoanedStateInterface> st;
      const auto cc = c->command_interface_configuration();
      const auto sc = c->state_interface_configuration();
      for (std::size_t i = 0; i < cc.names.size(); ++i) command.emplace_back(cc.names[i], &hw_command[i]);
      for (std::size_t i = 0; i < sc.names.size(); ++i) st.emplace_back(sc.names[i], &hw_state[i]);
      c->assign_interfaces(std::move(command), std::move(st));
      std::printf("activate %s\n", name_of(c->on_activate(state)));
    } else if (cmd == "ref") {
      trajectory_msgs::msg::JointTrajectoryPoint msg;
      for (auto * v : {&msg.positions, &msg.velocities, &msg.accelerations}) {
        std::size_t k;
        in >> k;
        v->resize(k);
        for (auto & x : *v) x = num(in);
      }
      sub->deliver(msg);
    } else if (cmd == "update") {
      const double period = num(in);
      for (double & v : hw_state) v = num(in);
      const rclcpp::Time now(0);
      const auto dt = rclcpp::Duration::from_nanoseconds(std::llround(period * 1e9));
      const std::size_t before = g_allocations;
      const auto r = c->update(now, dt);
      const std::size_t allocated = g_allocations - before;
      std::printf("update %s", r == controller_interface::return_type::OK ? "OK" : "ERROR");
      for (double v : hw_command) std::printf(" %.17g", v);
      std::printf(" fault %d %.17g %llu allocations %zu\n", static_cast<int>(c->fault()),
                  c->last_period(), static_cast<unsigned long long>(c->clipped_periods()),
                  allocated);
    } else if (cmd == "cleanup") {
      std::printf("cleanup %s\n", name_of(c->on_cleanup(state)));
    } else if (cmd == "error") {
      std::printf("error %s\n", name_of(c->on_error(state)));
    } else if (cmd == "reason") {
      std::printf("reason %s\n", c->fault_reason().c_str());
    } else if (cmd == "deactivate") {
      std::printf("deactivate %s", name_of(c->on_deactivate(state)));
      for (double v : hw_command) std::printf(" %.17g", v);
      std::printf("\n");
    }
  }
  return 0;
}
